"""One control step of the gantry (paper §3; pure): the newest tracking frame and the crane's
reported position in, a safe setpoint out.

detect (§2.1) → pick the marker (the one closest to the last, §3.1) → locate (eq. 5–8, with the
crater's height map) → predict (eq. 9–12 or ``default``) → guard (workspace, limits, stale
hold). The live service and the experiments call the same ``Controller``; neither repeats any
of these steps.

Three safeguards the paper did not need: a spot farther than ``marker_gate_mm`` from where the
robot is expected (its last measured position moved on with its last measured velocity, or
the motion capture's fix) is not the robot — a reflection; nor is one farther than
``mocap_gate_mm`` from the motion capture's fresh fix, whatever the frames show; and when
the marker has been lost for ``reacquire_after_s`` while the motion capture has a fresh fix
of the robot, the crane goes there at ``reacquire_speed_mm_s`` until the tracking camera
sees the marker again.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from itertools import chain
from typing import TYPE_CHECKING, Any

import numpy as np

from common.heightmap import HeightMap
from common.markers import Detection, Spot, closest, detect
from services.gantry.algorithms import make_predictor
from services.gantry.crane_track import CraneTrack, MarkerTrack, Paired
from services.gantry.crosscheck import CrossCheck
from services.gantry.locate import locate
from services.gantry.predict import Aiming, Estimate, Predictor
from services.gantry.safety import SetpointGuard, Workspace
from services.gantry.settings import GantrySettings

if TYPE_CHECKING:  # OpenCV's capture stays out of the core
    from common.capture import Frame

MAX_MARKERS = 20
PAPER_ALGORITHMS = frozenset({"basic", "pf-position", "pf-position-gauss", "pf-velocity"})
"""They keep eq. 8 as the paper computes it: the newest picture's offset added to the crane's
latest report, one position per control period. The others get every picture since the last
step, each with the crane's position when it was taken (``crane_track.py``)."""
MAX_EXTRAPOLATE_S = 0.05
"""A picture taken longer than this after the newest position of the crane (report or marker)
waits for the next step, when a newer one covers it: carried on from the last, the crane's
position is a guess — starting at 2 m/s² after the report, off by up to 2.6 mm here."""
PENDING_S = 0.5
"""A picture still waiting after this long is dropped (older than the bus lets one be)."""
MARKER_LOST_S = 0.25
"""The carriage's marker unseen this long before a picture: the reports pair it instead."""


@dataclass(frozen=True)
class Fix:
    """Where the motion capture saw something (the robot, ``stb/tracker/robot``; the crane's
    marker, ``stb/tracker/markers``), and how fast it went."""

    t_s: float
    xy_mm: np.ndarray
    v_mm_s: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def at(self, t_s: float) -> np.ndarray:
        """Where it was at ``t_s`` (moved on with its velocity; a short way only)."""
        return self.xy_mm + self.v_mm_s * (t_s - self.t_s)


@dataclass(frozen=True)
class Timing:
    """Where this control step stands in the crane controller's cycle."""

    taken_in_s: float  # until the controller takes the setpoint
    report_age_s: float  # how old the crane position it reported is now


@dataclass(frozen=True)
class Step:
    """What one control step saw, believed and decided."""

    setpoint: np.ndarray  # (x, y) mm: what to send the crane, always inside the workspace
    hold: bool
    reason: str  # why it holds; "" when tracking
    frame_s: float | None = None  # capture time of the frame used (None: no new frame)
    frame_shape: tuple[int, int] = (0, 0)  # its (height, width) in pixels
    detection: Detection | None = None
    measured_xyz: np.ndarray | None = None  # the robot's marker in the world (eq. 8)
    estimate: Estimate | None = None
    estimate_s: float | None = None  # capture time of the frame the estimate rests on
    reacquiring: bool = False  # going to the motion capture's fix: the marker is lost
    rejected_mm: float | None = None  # a spot refused: this far from where the robot should be
    disagreement: str = ""  # the tracking camera's fix and the motion capture's disagree: why


class Controller:
    """The gantry's control law with the state that belongs to it: the last marker pixel, the
    predictor's filters, the estimate and its age, the guard's last setpoint."""

    def __init__(self, settings: GantrySettings, heights: HeightMap,
                 predictor: Predictor | None = None) -> None:
        """``predictor``: None for the one ``settings`` name (the experiments pass others)."""
        s = settings
        self.settings, self.heights = s, heights
        self.camera, self.frame = s.tracking_camera, s.crane.frame()
        self.predictor = predictor or make_predictor(
            s.algorithm, seed=s.seed, max_horizon_s=s.max_horizon_s,
            particle=(s.pf_velocity if s.algorithm == "pf-velocity" else s.pf_position).options(),
            follow=s.default_filter.options())
        self.guard = SetpointGuard(
            Workspace(s.x_min_mm, s.x_max_mm, s.y_min_mm, s.y_max_mm, s.workspace_margin_mm),
            s.max_speed_mm_s, s.max_accel_mm_s2, s.stale_after_s)
        self.track = CraneTrack()
        self.marker_track = MarkerTrack()
        self._pending: list[Frame] = []  # pictures the crane's known positions do not cover yet
        self._observed: dict[str, Any] = {}  # the newest picture observed since the step
        self._fed_s = -float("inf")  # the newest picture fed to the predictor
        self.paired = self.predictor.name not in PAPER_ALGORITHMS
        self.estimate: Estimate | None = None
        self.estimate_s: float | None = None
        self.last_pixel: tuple[float, float] | None = None
        self._seen: list[tuple[float, np.ndarray]] = []  # the last two accepted positions
        self._fix: Fix | None = None
        self.tracking_check = CrossCheck(
            "the tracking camera's fix of the robot", s.fix_check_mm, s.check_window_s,
            s.mocap_max_age_s, "is [gantry.tracking_camera] this camera's? run stb gantry "
            "commission; or a reflection or a foreign frame")

    def restart(self) -> None:
        """The crane stopped on its own (watchdog, link loss, disabled): the next setpoint
        starts from where it stands."""
        self.guard.reset()

    def step(self, now_s: float, frame: Frame | None, crane_xy: np.ndarray,
             fix: Fix | None = None, timing: Timing | None = None,
             older: Sequence[Frame] = ()) -> Step:
        """One control period: ``frame`` is the newest frame not used yet (or None),
        ``crane_xy`` the crane's position as its controller reports it (mm), ``fix`` the
        motion capture's latest fix of the robot (or None), ``timing`` where the step
        stands in the controller's cycle (None: not known yet), ``older`` the frames that
        came before ``frame`` since the last step, newest first: the newest of them that
        shows the robot stands in for ``frame`` when that one does not (a stray or spoofed
        frame)."""
        crane_xy = np.asarray(crane_xy, dtype=float)
        s = self.settings
        self._fix = fix if fix is not None and abs(now_s - fix.t_s) <= s.mocap_max_age_s \
            else None
        seen: dict[str, Any] = {}
        if self.paired:
            fresh = [] if frame is None else [frame, *older]
            aim_s = self.aim_s(now_s, timing)
            seen = self._measure_paired(now_s, fresh, crane_xy, aim_s) or self._observed
            self._observed = {}
            if self.estimate is not None and isinstance(self.predictor, Aiming):
                self.estimate = self.predictor.aim(aim_s)  # for this step, new pictures or not
        elif frame is not None:
            seen = self._measure(chain([frame], older), crane_xy, self._horizon(timing))
        if seen:
            failing = self.tracking_check.failing(seen["frame_s"])
            seen["disagreement"] = "" if failing is None else failing.text(seen["frame_s"])
        if self._reacquire(now_s):
            assert self._fix is not None
            decision = self.guard.decide(now_s, self._fix.xy_mm, self._fix.t_s, crane_xy,
                                         max_speed_mm_s=s.reacquire_speed_mm_s)
            return Step(decision.setpoint, decision.hold, decision.reason or "",
                        estimate=self.estimate, estimate_s=self.estimate_s,
                        reacquiring=not decision.hold, **seen)
        decision = self.guard.decide(now_s, None if self.estimate is None else
                                     self.estimate.desired, self.estimate_s, crane_xy)
        return Step(decision.setpoint, decision.hold, decision.reason,
                    estimate=self.estimate, estimate_s=self.estimate_s, **seen)

    def _reacquire(self, now_s: float) -> bool:
        """Lost for long enough, and the motion capture knows where the robot is."""
        last_seen = self._seen[-1][0] if self._seen else None
        lost_s = float("inf") if last_seen is None else now_s - last_seen
        return self._fix is not None and lost_s > self.settings.reacquire_after_s

    def _horizon(self, timing: Timing | None) -> float | None:
        """How far ahead ``default`` aims: from when the crane was where its report says (the
        measured robot position is as old as that, whatever the frame's age, while the crane
        follows the robot) until it acts on this step's setpoint — the wait until the
        controller takes it, its reaction — and half a period (the setpoint stands for one)."""
        if timing is None:
            return None
        period = 1 / self.settings.control_hz
        return (timing.report_age_s + timing.taken_in_s + self.settings.reaction_s
                + 0.5 * period)

    def observe(self, now_s: float, frames: Sequence[Frame], crane_xy: np.ndarray,
                fix: Fix | None, aim_s: float) -> None:
        """Pictures as they come, between steps (the paired algorithms): located, fed to the
        predictor aiming at ``aim_s``; the next ``step`` reports the newest."""
        self._fix = fix if fix is not None and abs(now_s - fix.t_s) <= \
            self.settings.mocap_max_age_s else None
        seen = self._measure_paired(now_s, frames, np.asarray(crane_xy, dtype=float), aim_s)
        if seen:
            self._observed = seen

    def aim_s(self, now_s: float, timing: Timing | None) -> float:
        """When the crane will be where this step's setpoint sends it: the wait until the
        controller takes it, the crane's reaction, and half a period (the setpoint stands for
        one); before the controller's cycle is known, as if a period away."""
        s = self.settings
        period = 1 / s.control_hz
        taken_in = period if timing is None else timing.taken_in_s
        return now_s + min(taken_in + s.reaction_s + 0.5 * period, s.max_horizon_s)

    def _measure_paired(self, now_s: float, frames: Sequence[Frame], crane_xy: np.ndarray,
                        aim_s: float) -> dict[str, Any]:
        """Every picture since the last step, oldest first, each located from where the crane
        was when it was taken (one taken after the crane's newest known position waits for
        the next step); of pictures taken at the same moment (one sent again, changed) the one
        the motion capture agrees with. Each position found feeds the predictor."""
        looked: list[_Looked] = []
        noise: dict[float, float] = {}
        waiting, self._pending = self._pending, []
        for captured, image in sorted([*waiting, *frames], key=lambda f: f[0]):
            if captured <= self._fed_s or captured < now_s - PENDING_S:
                continue  # came too late: the predictor is past it
            paired, spread_s = self._crane_at(captured)
            if paired is not None and paired.extrapolated_s > MAX_EXTRAPOLATE_S \
                    or self._marker_due(captured):
                self._pending.append((captured, image))
                continue
            crane = crane_xy if paired is None else paired.xy_mm
            speed = 0.0 if paired is None else float(np.hypot(*paired.v_mm_s))
            noise[captured] = float(np.hypot(self.settings.default_filter.measurement_noise_mm,
                                             speed * spread_s))
            found = detect(image, max_markers=MAX_MARKERS)
            xyz, rejected, pixel = self._locate(found, crane, captured)
            looked.append(_Looked(captured, image, found, xyz, rejected, pixel,
                                  self._mocap_off(xyz, captured)))
        if not looked:  # every picture newer than the crane's reports
            return {}
        chosen = [_agreeing(group, self.tracking_check.tolerance_mm) for group in
                  _by_capture(looked)]
        used = [c for c in chosen if c is not None]
        for c in used:  # only these move the expectation the next spot is gated by: a
            assert c.xyz is not None  # copy that loses to its original must not drag it
            self._seen = [*self._seen[-1:], (c.captured, c.xyz[:2])]
            self.last_pixel = c.pixel
            self.estimate = self.predictor.update(c.captured, c.xyz[:2], aim_s - c.captured,
                                                  noise[c.captured])
        if used:  # a picture without the robot sets no order (a spoofed one is stamped "now")
            self._fed_s = used[-1].captured
        newest = used[-1] if used else looked[-1]
        if used:  # a picture without the robot is no news: the estimate ages until stale
            self.estimate_s = newest.captured if self.estimate is not None else None
        return {"frame_s": newest.captured, "frame_shape": newest.image.shape,
                "detection": newest.found, "measured_xyz": newest.xyz,
                "rejected_mm": newest.rejected}

    def _marker_due(self, t_s: float) -> bool:
        """Whether the motion capture's marker on the carriage, seen lately, has not yet come
        for ``t_s``: then the picture waits for it rather than take the roughly timed reports."""
        newest = self.marker_track.newest_s
        return newest is not None and newest < t_s - MAX_EXTRAPOLATE_S and \
            t_s - newest < MARKER_LOST_S

    def _crane_at(self, t_s: float) -> tuple[Paired | None, float]:
        """Where the crane was at ``t_s``: from the motion capture's marker on its carriage
        where that covers it, else from the controller's reports; and how far off in time
        that may be (the reports' ``report_spread_s``, the marker's none)."""
        marked = self.marker_track.at(t_s, ahead_s=MAX_EXTRAPOLATE_S)
        if marked is not None:
            return marked, 0.0
        return self.track.at(t_s), self.settings.report_spread_s

    def _measure(self, frames: Iterable[Frame], crane_xy: np.ndarray, horizon_s: float | None
                 ) -> dict[str, Any]:
        """The newest of ``frames`` that shows the robot where the motion capture sees it
        (within ``fix_check_mm``); of frames captured at the same time — a frame sent again,
        changed — the one nearest the motion capture's robot. A frame whose fix disagrees
        yields to an older one that agrees (a spoofed frame with a slowly drifting spot once
        dragged the crane 827 mm); none agreeing, the newest that shows the robot (the cross
        check's window judges it); none showing it, the newest."""
        looked: list[_Looked] = []
        for captured, image in frames:
            chosen = _agreeing(looked, self.tracking_check.tolerance_mm)
            if chosen is not None and captured < chosen.captured:
                break
            found = detect(image, max_markers=MAX_MARKERS)
            xyz, rejected, pixel = self._locate(found, crane_xy, captured)
            looked.append(_Looked(captured, image, found, xyz, rejected, pixel,
                                  self._mocap_off(xyz, captured)))
        assert looked, "at least one frame"
        chosen = (_agreeing(looked, self.tracking_check.tolerance_mm)
                  or next((f for f in looked if f.xyz is not None), looked[0]))
        captured, xyz = chosen.captured, chosen.xyz
        if xyz is not None:
            self._seen = [*self._seen[-1:], (captured, xyz[:2])]
            self.last_pixel = chosen.pixel
        self.estimate = self.predictor.update(captured, None if xyz is None else xyz[:2],
                                              horizon_s)
        self.estimate_s = captured if self.estimate is not None else None
        return {"frame_s": captured, "frame_shape": chosen.image.shape,
                "detection": chosen.found, "measured_xyz": xyz, "rejected_mm": chosen.rejected}

    def _mocap_off(self, xyz: np.ndarray | None, captured: float) -> float | None:
        """How far a fix is from the motion capture's robot at the frame's time (None: no fix,
        or no check)."""
        if xyz is None or self._fix is None or not self.tracking_check.enabled:
            return None
        return float(np.hypot(*(xyz[:2] - self._fix.at(captured))))

    def _locate(self, found: Detection, crane_xy: np.ndarray, captured: float
                ) -> tuple[np.ndarray | None, float | None, tuple[float, float] | None]:
        """The robot's marker in the world, or None; how far off a refused spot was; the
        marker's pixel."""
        if not found.markers:
            return None, None, None
        ref = self.last_pixel or self.camera.principal
        marker = closest(found.markers, *ref)  # the paper's choice (§3.1)
        assert marker is not None
        expected = self._expected(captured)
        xyz = self._world(marker, crane_xy)
        gate = self.settings.marker_gate_mm
        if expected is not None and gate > 0 and (
                off := float(np.hypot(*(xyz[:2] - expected)))) > gate:
            # a reflection? the robot may be another spot
            others = [(float(np.hypot(*(w[:2] - expected))), m, w) for m in found.markers
                      if m is not marker for w in [self._world(m, crane_xy)]]
            nearest = min(others, key=lambda o: o[0], default=None)
            if nearest is None or nearest[0] > gate:
                return None, off, None
            _, marker, xyz = nearest
        if (off_mocap := self._off_mocap(xyz)) is not None:
            return None, off_mocap, None
        if self._disagrees(xyz, captured):
            return None, self.tracking_check.off_mm, None
        return xyz, None, (marker.u, marker.v)

    def _disagrees(self, xyz: np.ndarray, captured: float) -> bool:
        """Compare the fix with the motion capture's robot at the frame's time; a fix that
        has disagreed for the check's window is not used until the two agree again."""
        if self._fix is None or not self.tracking_check.enabled:
            return False
        off = float(np.hypot(*(xyz[:2] - self._fix.at(captured))))
        self.tracking_check.observe(captured, off)
        return self.tracking_check.failing(captured) is not None

    def _off_mocap(self, xyz: np.ndarray) -> float | None:
        """How far the spot is from the motion capture's fresh fix, if farther than
        ``mocap_gate_mm``: then it is not the robot, whatever the tracking camera shows (a
        spoofed or stray frame; 428 spoofed frames once pulled the crane 1.57 m off)."""
        gate = self.settings.mocap_gate_mm
        if self._fix is None or gate <= 0:
            return None
        off = float(np.hypot(*(xyz[:2] - self._fix.xy_mm)))
        return off if off > gate else None

    def _world(self, marker: Spot, crane_xy: np.ndarray) -> np.ndarray:
        return locate(marker.u, marker.v, crane_xy, self.camera, self.frame, self.heights,
                      self.settings.marker_height_mm)

    def _expected(self, captured: float) -> np.ndarray | None:
        """Where the robot should be at ``captured``: its last measured position moved on
        with its last measured velocity (eq. 9), if recent; else the motion capture's fix."""
        if self._seen and captured - self._seen[-1][0] <= self.settings.reacquire_after_s:
            t1, p1 = self._seen[-1]
            if len(self._seen) == 2 and t1 > self._seen[0][0]:
                t0, p0 = self._seen[0]
                return p1 + (p1 - p0) / (t1 - t0) * (captured - t1)
            return p1
        return None if self._fix is None else self._fix.xy_mm


@dataclass(frozen=True)
class _Looked:
    """One frame looked at: when it was captured, what was found, where, how far from the
    motion capture's robot."""

    captured: float
    image: np.ndarray
    found: Detection
    xyz: np.ndarray | None
    rejected: float | None
    pixel: tuple[float, float] | None
    mocap_off_mm: float | None


def _by_capture(looked: Sequence[_Looked]) -> list[list[_Looked]]:
    """The pictures grouped by their capture time, in order."""
    groups: dict[float, list[_Looked]] = {}
    for f in looked:
        groups.setdefault(f.captured, []).append(f)
    return list(groups.values())


def _agreeing(looked: Sequence[_Looked], tolerance_mm: float) -> _Looked | None:
    """Of the frames (newest first) whose fix agrees with the motion capture (or cannot be
    compared), the newest; of those captured at that time, the nearest the motion capture."""
    agreeing = [f for f in looked if f.xyz is not None
                and (f.mocap_off_mm is None or f.mocap_off_mm <= tolerance_mm)]
    if not agreeing:
        return None
    newest = [f for f in agreeing if f.captured == agreeing[0].captured]
    return min(newest, key=lambda f: f.mocap_off_mm or 0.0)
