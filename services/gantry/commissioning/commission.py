"""Driving a crane's first day (``stb gantry commission``): the crane moved from stop to stop,
and at each, once it stands still, what its controller reports, where the motion capture sees
the marker on its carriage and the targets below it, and where the tracking camera sees the
targets (the fits: ``geometry_fit.py``; the dynamics: ``identify_run.py``)."""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from common import keys
from common import messages as m
from common.bus import Bus
from common.crane_frame import CraneFrame
from common.markers import Spot, detect
from common.tracking_camera import TrackingCameraModel
from services.gantry.commissioning.geometry_fit import CameraFit, Sighting, fit_camera
from services.gantry.commissioning.identify_run import CommissioningError
from services.gantry.crane import RegisterCrane
from services.gantry.frames import FrameInbox, decode
from services.gantry.reading import CraneError, CraneReading

REST_MM, REST_MM_S, REST_FOR_S = 2.0, 2.0, 0.3  # standing still: near the target, not moving
MOVE_TIMEOUT_S = 15.0
MOCAP_S = 0.4  # the motion capture's positions averaged over this, at rest
FRAMES = 3  # tracking frames per stop, their spots' median
GATE_PX = 70.0  # a spot this far from where a target should appear is not it
GRID = (5, 4)  # camera stops per target across the image (columns, rows)
SPAN = 0.45  # of the image's width and height, each way from its middle
PROBE_GRID, PROBE_SPAN = (2, 2), 0.08  # the first stops per target: near the image's middle
CENTRAL = 0.6  # the first camera fit takes targets within this share of the image's middle
REPLAN = 0.05  # a probe's focal length this far off the lab file's: a note says to mend it


@dataclass
class Stand:
    """What a stop gave: the crane's report (its own frame) and the motion capture's markers."""

    reading: CraneReading
    mocap: dict[str, np.ndarray]
    spots: list[list[Spot]]


class Watch:
    """The crane, the motion capture's labelled markers and the tracking camera's frames."""

    def __init__(self, crane: RegisterCrane, bus: Bus) -> None:
        self.crane = crane
        self._markers: deque[tuple[float, dict[str, np.ndarray]]] = deque(maxlen=2000)
        self.frames = FrameInbox()
        self._lock = threading.Lock()
        bus.subscribe(keys.TRACKER_MARKERS, self._on_markers, latest=False)
        bus.subscribe(keys.GANTRY_FRAME, self._on_frame)

    def _on_markers(self, msg: m.MarkerFrame) -> None:
        seen = {mk.label: np.array([mk.x_mm, mk.y_mm, mk.z_mm]) for mk in msg.markers
                if mk.label}
        with self._lock:
            self._markers.append((time.monotonic(), seen))

    def _on_frame(self, msg: m.CameraFrame) -> None:
        frame = decode(msg)
        if frame is not None:
            self.frames.put(frame)

    def mocap(self, labels: Sequence[str], seconds: float = MOCAP_S) -> dict[str, np.ndarray]:
        """Each label's mean position over the next ``seconds``; a label not seen: missing."""
        since = time.monotonic()
        time.sleep(seconds)
        with self._lock:
            recent = [seen for t, seen in self._markers if t >= since]
        return {label: np.mean(found, axis=0) for label in labels
                if (found := [seen[label] for seen in recent if label in seen])}

    def spots(self, count: int = FRAMES, timeout_s: float = 2.0) -> list[list[Spot]]:
        """The spots in each of the next ``count`` frames captured from now."""
        since, out = time.time(), list[list[Spot]]()
        deadline = time.monotonic() + timeout_s
        while len(out) < count and time.monotonic() < deadline:
            frame = self.frames.take()
            if frame is None:
                time.sleep(0.01)
            elif frame[0] >= since:
                out.append(list(detect(frame[1], max_markers=20).markers))
        return out

    def move(self, raw_xy: np.ndarray) -> CraneReading:
        """The crane to ``raw_xy`` (its own frame), once it stands still there."""
        self.crane.write_setpoint(*raw_xy)
        deadline = time.monotonic() + MOVE_TIMEOUT_S
        still_since = None
        while time.monotonic() < deadline:
            reading = self.crane.read()
            close = np.hypot(reading.x_mm - raw_xy[0], reading.y_mm - raw_xy[1]) <= REST_MM
            if close and np.hypot(reading.vx_mm_s, reading.vy_mm_s) <= REST_MM_S:
                still_since = still_since or time.monotonic()
                if time.monotonic() - still_since >= REST_FOR_S:
                    return reading
            else:
                still_since = None
            time.sleep(0.02)
        raise CommissioningError(f"the crane did not come to rest at ({raw_xy[0]:.0f}, "
                                 f"{raw_xy[1]:.0f}) within {MOVE_TIMEOUT_S:g} s (its travel "
                                 "limits? a fault?)")


@contextlib.contextmanager
def heartbeat(crane: RegisterCrane) -> Iterator[None]:
    """The crane's watchdog fed while the block runs; the crane disabled after it."""
    stop = threading.Event()

    def beat() -> None:
        while not stop.wait(0.1):
            with contextlib.suppress(CraneError):
                crane.heartbeat()

    thread = threading.Thread(target=beat, name="heartbeat", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(2)
        with contextlib.suppress(CraneError):
            crane.disable()


def frame_pattern(start_raw: np.ndarray, half_mm: float) -> list[np.ndarray]:
    """Nine stops on a square around where the crane stands, in its own frame."""
    return [start_raw + [dx, dy] for dy in (-half_mm, 0.0, half_mm)
            for dx in (-half_mm, 0.0, half_mm)]


def camera_pattern(targets_xyz: np.ndarray, nominal: TrackingCameraModel,
                   grid: tuple[int, int] = GRID, span: float = SPAN) -> list[np.ndarray]:
    """Where the crane's reported point goes (world) so that each target in turn crosses the
    whole image, its corners too (where the lens bends most): for each, a grid of ``grid``
    positions that puts it within ``span`` of the image's half-size each way (at its own depth,
    so its own footprint), row by row in a snake."""
    stops = []
    cols, rows = grid
    for target in np.atleast_2d(targets_xyz):
        depth = nominal.height_mm - target[2]
        footprint = np.array([nominal.width_px, nominal.height_px]) * (
            depth * nominal.pixel_mm / nominal.focal_mm)
        for r, fy in enumerate(np.linspace(-span, span, rows)):
            xs = np.linspace(-span, span, cols)
            for fx in (xs if r % 2 == 0 else xs[::-1]):
                stops.append(target[:2] - np.array([fx, fy]) * footprint)
    return stops


def sightings_at(stand_xy: np.ndarray, spots: list[list[Spot]], targets: dict[str, np.ndarray],
                 camera: TrackingCameraModel, frame: CraneFrame) -> list[Sighting]:
    """Each target's spot in the frames at one stop, by where the camera should show it: the
    nearest spot within ``GATE_PX`` when no other is as near; its median over the frames."""
    out = []
    for xyz in targets.values():
        expected = camera.project(xyz, stand_xy, frame)[0][0]
        found = []
        for frame_spots in spots:
            near = sorted((float(np.hypot(s.u - expected[0], s.v - expected[1])), s.u, s.v)
                          for s in frame_spots)
            near = [n for n in near if n[0] <= GATE_PX]
            if len(near) == 1:
                found.append(near[0][1:])
        if len(found) >= max(1, len(spots) - 1):
            out.append(Sighting(stand_xy, xyz, np.median(np.array(found), axis=0)))
    return out


Stands = list[tuple[np.ndarray, list[list[Spot]]]]
"""What each camera stop saw: where the crane stood (world x, y) and the frames' spots."""


def survey_camera(visit: Callable[[list[np.ndarray]], Stands], targets: dict[str, np.ndarray],
                  nominal: TrackingCameraModel, frame: CraneFrame, height_mm: float, *,
                  max_residual_px: float = 1.0, notes: list[str] | None = None) -> CameraFit:
    """The camera's lens and mount from the stops ``visit`` takes the crane to (it returns
    what each saw). A probe first (``PROBE_GRID`` stops per target, each target near the
    image's middle, where any lens of 6–12 mm shows it when the lab file says 8): its focal
    length plans the survey's stops, so that each target crosses the image's corners whatever
    the lens (a 12 mm lens where the lab file says 8 sees two thirds of the ground planned for
    8 mm, and no corner). The camera is fitted from the probe's and the survey's stops; a
    probe more than ``REPLAN`` off the lab file's focal length is noted."""
    targets_xyz = np.array(list(targets.values()))
    probe = visit(camera_pattern(targets_xyz, nominal, PROBE_GRID, PROBE_SPAN))
    first = _first_fit(probe, targets, nominal, frame, height_mm)
    if notes is not None and abs(first.camera.focal_mm / nominal.focal_mm - 1.0) > REPLAN:
        notes.append(f"camera: the lens measured {first.camera.focal_mm:.2f} mm where the lab "
                     f"file says {nominal.focal_mm:g} mm; the stops planned for the lens measured")
    planned = nominal.model_copy(update={"focal_mm": first.camera.focal_mm})
    stands = probe + visit(camera_pattern(targets_xyz, planned))
    return camera_from_stands(stands, targets, planned, frame, height_mm,
                              max_residual_px=max_residual_px)


def _first_fit(stands: Stands, targets: dict[str, np.ndarray], nominal: TrackingCameraModel,
               frame: CraneFrame, height_mm: float) -> CameraFit:
    """Without distortion, from the targets near the image's middle, where the nominal
    camera finds them."""
    middle = np.array(nominal.principal)
    size = np.array([nominal.width_px, nominal.height_px])
    central = [s for stand, spots in stands
               for s in sightings_at(stand, spots, targets, nominal, frame)
               if np.all(np.abs(s.pixel - middle) <= CENTRAL * size / 2)]
    return fit_camera(central, nominal, frame, height_mm, distortion=False,
                      max_residual_px=10.0)


def camera_from_stands(stands: Stands, targets: dict[str, np.ndarray],
                       nominal: TrackingCameraModel, frame: CraneFrame, height_mm: float, *,
                       max_residual_px: float = 1.0) -> CameraFit:
    """The camera from what each stop saw: first without distortion (``_first_fit``), then
    from everything every stop saw, found through that first fit."""
    first = _first_fit(stands, targets, nominal, frame, height_mm)
    found = [s for stand, spots in stands
             for s in sightings_at(stand, spots, targets, first.camera, frame)]
    return fit_camera(found, nominal, frame, height_mm, max_residual_px=max_residual_px)


def confirm(yes: bool, question: str, ask: Callable[[str], str] = input) -> None:
    """The operator's go before the crane moves (``yes``: given beforehand)."""
    if yes:
        return
    if ask(f"{question} [y/N] ").strip().lower() not in ("y", "yes"):
        raise CommissioningError("cancelled: the crane did not move", 1)
