"""Driving and recording a commissioning run (``stb gantry identify``): the crane polled at
100 Hz, the tracking camera's marker in every frame, the planned moves; then the figures
(``identify.py`` does the arithmetic)."""

from __future__ import annotations

import argparse
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from common import keys
from common.bus import Bus
from common.errors import ConfigError
from common.heightmap import HeightMap
from common.markers import closest, detect, warm_up
from common.node import configure_logging
from common.settings import load_settings
from services.args import EXIT_CONFIG, overrides_from
from services.gantry.commissioning.identify import (
    Figure,
    Series,
    cycle_tick,
    ramp_lag,
    report_timing,
    sampling_period,
    set_off,
    tick_after,
)
from services.gantry.crane import RegisterCrane
from services.gantry.frames import FrameInbox, FrameSource, OpenCvFrames
from services.gantry.reading import CraneError, CraneReading
from services.gantry.settings import GantrySettings

POLL_S = 0.01
STEP_MM = 100.0
TICK_MARGIN = 0.1
"""Of the sampling period: no step is written this near the controller's tick, either side (a write
held up a few milliseconds on a busy machine would miss it, and its reaction be a period longer)."""
RAMP_MM_S = 100.0


class CommissioningError(Exception):
    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(message)
        self.code = code


def lab_of(args: argparse.Namespace) -> tuple[GantrySettings, HeightMap]:
    """The gantry's settings (from --lab and the common flags) and its height map, logging
    configured and the detector loaded; a bad one is a ``CommissioningError`` (exit 2)."""
    try:
        settings = load_settings(GantrySettings, args.lab, overrides_from(args))
        heights = HeightMap.load(settings.height_map)
    except (ConfigError, ValueError) as err:
        raise CommissioningError(str(err), EXIT_CONFIG) from err
    configure_logging(settings.log_level)
    warm_up()
    return settings, heights


@dataclass
class Plan:
    """What was sent when: step setpoints, long moves, the ramp."""

    steps_s: list[float] = field(default_factory=list)
    moves_s: list[float] = field(default_factory=list)
    ramp_s: tuple[float, float] = (0.0, 0.0)
    ramp_from_mm: float = 0.0  # x where the ramp starts


class Recorder:
    """The crane polled every ``POLL_S`` and the marker in every frame, on threads of their
    own, while the moves run."""

    def __init__(self, settings: GantrySettings, heights: HeightMap, crane: RegisterCrane,
                 bus: Bus | None) -> None:
        self.settings, self.heights, self.crane = settings, heights, crane
        self.lens, self.frame = settings.tracking_camera, settings.crane.frame()
        self.readings: list[tuple[float, CraneReading]] = []
        self.marks: list[tuple[float, float, float]] = []  # capture time, u, v
        self._stop = threading.Event()
        self.frames: FrameSource
        if bus is None:
            self.frames = OpenCvFrames(settings.frames.removeprefix("opencv:"), self._stop)
        else:
            inbox = self.frames = FrameInbox()
            bus.subscribe(keys.GANTRY_FRAME, inbox.put_message)
        self._threads = [threading.Thread(target=self._poll, daemon=True),
                         threading.Thread(target=self._look, daemon=True)]

    def start(self) -> None:
        for thread in self._threads:
            thread.start()

    def stop(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(2)

    def _poll(self) -> None:
        while not self._stop.wait(POLL_S):
            before = time.time()
            try:
                reading = self.crane.read()
            except CraneError:
                continue
            self.readings.append((0.5 * (before + time.time()), reading))  # when it was read

    def _look(self) -> None:
        last: tuple[float, float] | None = None
        while not self._stop.wait(0.005):
            frame = self.frames.take()
            if frame is None:
                continue
            found = detect(frame[1], max_markers=20)
            marker = closest(found.markers, *(last or self.lens.principal))
            if marker is not None:
                last = (marker.u, marker.v)
                self.marks.append((frame[0], marker.u, marker.v))

    # --- before moving -------------------------------------------------------------------------

    def ready_to_move(self, wait_s: float = 3.0) -> np.ndarray:
        """Where the crane stands, once it is clear that moving it is safe and measurable."""
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and (len(self.readings) < 10 or len(self.marks) < 10):
            time.sleep(0.05)
        if not self.readings:
            raise CommissioningError("the crane controller does not answer", 3)
        reading = self.readings[-1][1]
        if reading.enabled:
            raise CommissioningError("the crane is enabled: is the gantry service driving it? "
                                     "stop it (stb gantry disarm, then stop the service)")
        if not reading.safety_ok or reading.latched_faults:
            raise CommissioningError(f"the crane cannot move: safety circuit "
                                     f"{'closed' if reading.safety_ok else 'open'}, faults "
                                     f"{reading.fault_names} (reset them at the controller or "
                                     "with stb gantry reset)")
        recent = [m for m in self.marks if m[0] > time.time() - 1.5]
        if len(recent) < 5:
            raise CommissioningError("no marker in the tracking camera's view: park the robot "
                                     "(or put a marker) below the crane", 3)
        pixels = np.array([m[1:] for m in recent])
        if np.max(np.ptp(pixels, axis=0)) > 2.0:
            raise CommissioningError("the marker below the crane moves: it must stand still")
        return np.array([reading.x_mm, reading.y_mm])

    def duration_s(self, steps: int) -> float:
        return 1.5 + steps * 1.25 + 3 * 2.5 + 2 * 4.0 + 1.0

    # --- moving --------------------------------------------------------------------------------

    def sampling_times(self, since_s: float = 0.0) -> np.ndarray:
        """When the controller took a setpoint (its counter went up), ± half a poll."""
        out, last = [], None
        for t, r in list(self.readings):
            if last is not None and r.setpoints_taken != last and t >= since_s:
                out.append(t - POLL_S / 2)
            last = r.setpoints_taken
        return np.array(out)

    # --- the camera's and the controller's positions -------------------------------------------

    def camera(self, axis: int, start: np.ndarray) -> Series:
        """The crane's true position along ``axis`` from the marker standing still below:
        where the marker is (the crane at rest at ``start``, its offset then) less its
        offset now (eq. 7 turned round)."""
        marks = np.array(self.marks)
        first = marks[0]
        z = self._marker_distance(start, first[1], first[2])
        offsets = np.array([self._offset(u, v, z) for _, u, v in marks])
        at_rest = marks[:, 0] <= marks[0, 0] + 0.5
        marker = start + np.median(offsets[at_rest], axis=0)
        return Series(marks[:, 0], marker[axis] - offsets[:, axis])

    def _offset(self, u: float, v: float, z: float) -> np.ndarray:
        """The marker from the crane's reported point (world axes), z below the lens."""
        return (self.lens.lens_xy(np.zeros(2), self.frame)
                + self.lens.ground_offset(u, v, z, self.frame))

    def _marker_distance(self, crane: np.ndarray, u: float, v: float) -> float:
        s, height = self.settings, self.lens.height_mm
        z = height - s.marker_height_mm
        for _ in range(4):
            xy = crane + self._offset(u, v, z)
            ground = float(self.heights.height_at(xy[0], xy[1]))
            z = height - (ground + s.marker_height_mm)
        return z

    def reported(self, axis: int) -> Series:
        """The reported position at the moments the controller published a new one."""
        t, x, last = [], [], None
        for when, r in list(self.readings):
            value = (r.x_mm, r.y_mm)[axis]
            if last is not None and value != last:
                t.append(when - POLL_S / 2)
                x.append(value)
            last = value
        return Series(np.array(t), np.array(x))

    def velocity(self, axis: int) -> Series:
        data = np.array([(t, (r.vx_mm_s, r.vy_mm_s)[axis]) for t, r in list(self.readings)])
        return Series(data[:, 0], data[:, 1])


def run_moves(recorder: Recorder, start: np.ndarray, box: float, steps: int,
              progress: Callable[[str], None]) -> Plan:
    """Steps, long moves and a ramp along x within ±box/2 of ``start``; the crane enabled
    for them and disabled after."""
    crane, plan = recorder.crane, Plan()
    crane.enable()
    crane.write_setpoint(*start)
    time.sleep(1.5)  # the controller takes the standing setpoint: its sampling shows
    period = float(np.median(np.diff(recorder.sampling_times()))) if len(
        recorder.sampling_times()) > 2 else 0.25
    step = min(STEP_MM, box / 4)
    progress(f"{steps} steps of {step:.0f} mm (sampling every {period:.3f} s)")
    for k in range(steps):
        # writes spread evenly over the cycle, clear of its tick by TICK_MARGIN both ways
        phase = (TICK_MARGIN + (1 - 2 * TICK_MARGIN) * (k + 0.5) / steps) * period
        due = cycle_tick(recorder.sampling_times(), period, time.time()) + phase
        while due < time.time() + POLL_S:
            due += period
        time.sleep(max(due - time.time(), 0.0))
        target = start + [step if k % 2 == 0 else 0.0, 0.0]
        plan.steps_s.append(time.time())
        crane.write_setpoint(*target)
        time.sleep(1.0)
    progress(f"long moves across {box:.0f} mm")
    for x in (box / 2, -box / 2, 0.0):
        plan.moves_s.append(time.time())
        crane.write_setpoint(*(start + [x, 0.0]))
        time.sleep(2.5)
    progress(f"a ramp at {RAMP_MM_S:.0f} mm/s")
    t0 = time.time()
    plan.ramp_s, plan.ramp_from_mm = (t0, t0 + box / RAMP_MM_S), float(start[0] - box / 2)
    while (now := time.time()) < plan.ramp_s[1]:
        crane.write_setpoint(plan.ramp_from_mm + RAMP_MM_S * (now - t0), float(start[1]))
        time.sleep(0.05)
    crane.write_setpoint(*start)
    time.sleep(3.0)
    crane.disable()
    return plan


@dataclass(frozen=True)
class Measurements:
    sampling_s: Figure
    dead_s: Figure
    reaction_s: Figure
    following_s: Figure
    report_age_s: Figure
    report_spread_s: Figure
    top_speed_mm_s: Figure
    accel_mm_s2: Figure

    @classmethod
    def of(cls, recorder: Recorder, plan: Plan, settings: GantrySettings) -> Measurements:
        start = np.array([recorder.readings[0][1].x_mm, recorder.readings[0][1].y_mm])
        camera = recorder.camera(0, start)
        speed = recorder.velocity(0)
        top = float(np.percentile(np.abs(speed.values), 99)) if len(speed.values) else 0.0
        top_figure = Figure.of(np.abs(speed.values)[np.abs(speed.values) >= 0.95 * top])
        moves = [o for t in plan.moves_s if (o := set_off(camera, t, t + 2.0, top))]
        taken = recorder.sampling_times()
        sampling = sampling_period(taken)
        period = sampling.median if sampling.n > 1 else 0.0
        dead, reaction = [], []
        for t_w in plan.steps_s:
            sampled = tick_after(taken, period, t_w) if period > 0 else None
            began = set_off(camera, t_w, t_w + 1.0, top)
            if sampled is not None and began is not None:
                dead.append(began.t_s - sampled)
                # a write at a random moment waits half a period for the tick, on average (the
                # steps' own waits are their planned phases, not a random moment's)
                reaction.append(began.t_s - sampled + period / 2)
        accel = Figure.of([o.accel_mm_s2 for o in moves])
        ramp = (recorder.reported(0).t_s >= plan.ramp_s[0]) & (
            recorder.reported(0).t_s <= plan.ramp_s[1] + 1.0)
        reported = recorder.reported(0)
        age, spread = report_timing(Series(reported.t_s[ramp], reported.values[ramp]), camera,
                                    RAMP_MM_S)
        trails = ramp_lag(camera, plan.ramp_s, plan.ramp_from_mm, RAMP_MM_S)
        follows = [] if trails is None else [trails - sampling.median / 2]
        return cls(sampling, Figure.of(dead), Figure.of(reaction), Figure.of(follows),
                   Figure.of([age]), Figure.of([spread]), top_figure, accel)

    def table(self) -> str:
        rows = [("sampling period", self.sampling_s, "s"), ("dead time", self.dead_s, "s"),
                ("reaction (write → motion)", self.reaction_s, "s"),
                ("following (taken → follows)", self.following_s, "s"),
                ("report age", self.report_age_s, "s"),
                ("report age's spread", self.report_spread_s, "s"),
                ("top speed", self.top_speed_mm_s, "mm/s"),
                ("acceleration", self.accel_mm_s2, "mm/s²")]
        return "\n".join(f"{name:<27} {f.median:10.3f} {unit:<6} spread {f.spread:.3f} "
                         f"(n = {f.n})" for name, f, unit in rows)

    def toml(self) -> str:
        return (f"[gantry]\ncontrol_hz = {1 / self.sampling_s.median:.3g}\n"
                f"reaction_s = {max(self.following_s.median, 0.0):.3f}  # setpoint taken → "
                "crane follows\n"
                f"report_age_s = {self.report_age_s.median:.3f}\n"
                f"report_spread_s = {self.report_spread_s.median:.3f}\n"
                f"max_speed_mm_s = {self.top_speed_mm_s.median:.0f}\n"
                f"max_accel_mm_s2 = {self.accel_mm_s2.median:.0f}\n"
                f"# total reaction (write → motion) {self.reaction_s.median:.3f} s\n")
