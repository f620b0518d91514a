"""The gantry's control loop over any crane and any frame source (the live service's and the
experiments' alike).

Polled faster than the control period (``poll_hz``), it reads the crane controller's report,
carries out the operator's commands and the stops the crane makes by itself (``ModeKeeper``),
lets ``CycleSync`` decide when to tick (a fixed time after the report), and on a tick hands
the newest frame and the reported position to the ``Controller`` — and, only while armed, the
setpoint to the crane.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from common.names import GantryCommandName
from services.gantry.command_rate import CommandRate
from services.gantry.control import Controller, Fix, Step, Timing
from services.gantry.crosscheck import CrossCheck
from services.gantry.cycle import CycleSync, tick_offset_s
from services.gantry.modes import Action, Decision, Facts, ModeKeeper
from services.gantry.reading import Crane, CraneError, CraneReading
from services.gantry.safety import TargetCheck
from services.gantry.settings import GantrySettings

if TYPE_CHECKING:  # the frames' threads and JPEG decoding stay out of the core
    from common.capture import Frame
    from services.gantry.frames import FrameSource

log = logging.getLogger(__name__)

MARKER_FRESH_S = 0.15
"""A motion-capture sample of the crane's marker older than this is not compared."""
COMMAND_MAX_AGE_S = 2.0
"""An arm, disarm or reset older than this is refused (it was meant for another moment);
a stop never is."""
MAX_REFUSALS_QUEUED = 100
"""Refusals for too many commands answered per poll at most (a flood's rest is only counted)."""


@dataclass(frozen=True)
class Request:
    command: GantryCommandName
    by: str  # the audit's name for the sender
    reason: str = ""
    id: str = ""
    sent_s: float | None = None  # when the operator sent it (None: now)
    sender: str | None = None
    """Who really sent it, as its command rate counts it (None: ``by``, for commands from
    within the process)."""

    @property
    def rate_key(self) -> str:
        return self.by if self.sender is None else self.sender


@dataclass(frozen=True)
class Reply:
    request: Request
    decision: Decision


@dataclass(frozen=True)
class Tick:
    """One poll's outcome worth reporting: the report it read, what the controller did (on a
    control tick), the replies to commands and the stops by the crane itself, or why the crane
    could not be reached (``error``)."""

    now_s: float
    reading: CraneReading | None
    step: Step | None = None
    error: CraneError | None = None
    replies: tuple[Reply, ...] = ()
    changes: tuple[Decision, ...] = field(default=())  # mode changes the crane caused


class GantryLoop:
    def __init__(self, settings: GantrySettings, crane: Crane, frames: FrameSource,
                 controller: Controller, now_s: float,
                 fix: Callable[[], Fix | None] = lambda: None,
                 crane_marker: Callable[[], Fix | None] = lambda: None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.settings = settings
        self.crane, self.frames, self.controller, self.fix = crane, frames, controller, fix
        self.crane_marker = crane_marker
        self._marker_compared_s = -float("inf")
        self.crane_check = CrossCheck(
            "the crane's position through [gantry.crane]'s frame", settings.crane_check_mm,
            settings.check_window_s, settings.mocap_max_age_s,
            f"is the frame this crane's, and the motion capture's marker "
            f"{settings.crane_marker!r} on its carriage? run stb gantry commission")
        period = 1 / settings.control_hz
        self.sync = CycleSync(period, tick_offset_s(settings.after_report_s, period,
                                                    controller.paired))
        self.modes = ModeKeeper(now_s)
        self.targets = TargetCheck(settings.target_check_mm)
        self.reachable = True
        self.reading: CraneReading | None = None
        self._error: CraneError | None = None  # of the last tick's setpoint
        self._requests: deque[Request] = deque()
        self._too_many: deque[Request] = deque()  # refused by the rate, answered at the poll
        self.rate = CommandRate(settings.command_per_s, settings.command_burst)
        self.clock = clock
        self.last_reply: tuple[float, Reply] | None = None  # (when, the last command's answer)
        self._lock = threading.Lock()

    @property
    def armed(self) -> bool:
        return self.modes.mode == "armed"

    def request(self, request: Request) -> None:
        """An operator's command, carried out at the next poll (from any thread) if its
        sender has not sent too many (``CommandRate``)."""
        with self._lock:
            admission = self.rate.admit(request.rate_key, self.clock(),
                                        always=request.command == "stop")
            if admission.admitted:
                self._requests.append(request)
            elif len(self._too_many) < MAX_REFUSALS_QUEUED:
                self._too_many.append(request)
        if admission.report:
            log.warning("too many commands from %r: at most %g a second after %d at once; "
                        "the rest of this flood is answered \"too many\" without more log",
                        request.rate_key[:128], self.rate.per_s, self.rate.burst)

    def next_poll_s(self, due_s: float, wait_s: float) -> float:
        """When to poll next after the poll due at ``due_s`` (scheduling clock): ``wait_s``
        later (a dithered poll period, ``cycle.dithered_period_s``), or at the next tick if
        that comes sooner — a tick does not wait for a poll, so its setpoint reaches the
        controller ``WRITE_MARGIN_S`` before it takes one, as planned."""
        tick = self.sync.next_tick_s
        return min(due_s + wait_s, tick) if tick is not None and tick > due_s else \
            due_s + wait_s

    def poll(self, now_s: float, monotonic_s: float | None = None) -> Tick | None:
        """Read the controller's report, carry out commands and stops, tick when due.
        ``now_s`` is the frames' clock (their capture times), ``monotonic_s`` the scheduling
        clock (default: ``now_s``). Returns None when there is nothing to report."""
        mono = now_s if monotonic_s is None else monotonic_s
        error: CraneError | None = None
        before = self.clock()
        try:
            self.reading = self.crane.read()
        except CraneError as err:
            self.reading, error = None, err
        # when the controller answered, about: under load a read takes milliseconds, and a
        # report's change seen by it is dated by it (``CycleSync``), the ticks' phase with it
        read_s = mono + 0.5 * (self.clock() - before)
        self._compare_crane(now_s)
        replies = self._carry_out_requests(now_s)
        changes = self._observe(now_s)
        if self.reading is not None:
            self._track(now_s, mono, read_s, self.reading)
            if self.controller.paired:
                self._observe_frames(now_s, mono, self.reading)
        due = self.sync.due(mono)
        if not due and not replies and not changes:
            return None
        if self.reading is None:
            assert error is not None
            return Tick(now_s, None, None, self._unreachable(error), replies, changes)
        step = self._tick(now_s, mono, self.reading) if due else None
        return Tick(now_s, self.reading, step, self._error, replies, changes)

    # --- commands and stops ----------------------------------------------------------------

    def _carry_out_requests(self, now_s: float) -> tuple[Reply, ...]:
        with self._lock:
            requests, self._requests = list(self._requests), deque()
            too_many, self._too_many = list(self._too_many), deque()
        replies = tuple(Reply(r, self._carry_out(r, now_s)) for r in requests) + tuple(
            Reply(r, Decision(False, self.modes.mode, Action.NONE,
                              f"too many commands from {r.rate_key[:64]!r}: at most "
                              f"{self.rate.per_s:g} a second; send it again later"))
            for r in too_many)
        if replies:
            self.last_reply = (now_s, replies[-1])  # the audit in the gantry's state
        return replies

    def _carry_out(self, request: Request, now_s: float) -> Decision:
        age = 0.0 if request.sent_s is None else now_s - request.sent_s
        if request.command != "stop" and abs(age) > COMMAND_MAX_AGE_S:
            return Decision(False, self.modes.mode, Action.NONE,
                            f"sent {age:.1f} s ago: too old to act on, send it again")
        estimate_s, fix = self.controller.estimate_s, self.fix()
        facts = Facts(self.reading, None if estimate_s is None else now_s - estimate_s,
                      self.settings.stale_after_s, None if fix is None else now_s - fix.t_s,
                      geometry=self.geometry(now_s))
        before = (self.modes.mode, self.modes.by, self.modes.reason, self.modes.since_s)
        decision = self.modes.command(request.command, request.by, request.reason, now_s, facts)
        if not decision.accepted:
            log.warning("%s from %s refused: %s", request.command, request.by, decision.detail)
            return decision
        failed = self._act(decision.action)
        if failed is not None and request.command == "stop":
            detail = (f"stopped; the controller did not answer ({failed}): its watchdog stops "
                      "the crane")
            return Decision(True, self.modes.mode, decision.action, detail)
        if failed is not None:
            self.modes.mode, self.modes.by, self.modes.reason, self.modes.since_s = before
            log.warning("%s from %s failed: %s", request.command, request.by, failed)
            return Decision(False, self.modes.mode, Action.NONE,
                            f"the crane controller did not take it: {failed}")
        log.info("%s by %s: now %s (%s)", request.command, request.by, decision.mode,
                 decision.detail)
        return decision

    def _compare_crane(self, now_s: float) -> None:
        """The crane's reported position (through its frame) against the motion capture's
        marker on its carriage, both taken to the marker's time: each new marker sample once,
        and only a fresh one (the report's velocity carries it a short way only)."""
        marker = self.crane_marker()
        if marker is not None and self.settings.crane_check_mm > 0:
            self.controller.marker_track.add(marker.t_s, marker.xy_mm)
        if self.reading is None or marker is None or now_s - marker.t_s > MARKER_FRESH_S \
                or marker.t_s <= self._marker_compared_s:
            return
        self._marker_compared_s = marker.t_s
        reported_s = now_s - self.settings.report_age_s
        crane = np.array([self.reading.x_mm, self.reading.y_mm]) + np.array(
            [self.reading.vx_mm_s, self.reading.vy_mm_s]) * (marker.t_s - reported_s)
        self.crane_check.observe(now_s, float(np.hypot(*(crane - marker.xy_mm))))

    def geometry(self, now_s: float) -> str | None:
        """Why the crane's frame or the tracking camera's model may not be trusted to arm:
        the crane's cross-check (it must have a recent comparison), the tracking camera's
        (if the robot is in view)."""
        return (self.crane_check.verdict(now_s)
                or self.controller.tracking_check.verdict(now_s, needed=False))

    def _observe(self, now_s: float) -> tuple[Decision, ...]:
        if self.reading is None:
            return ()
        stop = self.modes.observe(self.reading, now_s)
        if stop is None and self.armed:
            foreign = (self.targets.observe_written(self.reading)
                       or self.targets.observe(self.reading))
            stop = None if foreign is None else self.modes.halt(foreign, now_s)
        if stop is None and self.armed and (off := self.crane_check.failing(now_s)):
            stop = self.modes.halt(off.text(now_s), now_s)
        if stop is None:
            return ()
        log.warning("crane stopped: %s; the gantry is stopped until an operator resets it",
                    stop.detail)
        self._act(stop.action)
        return (stop,)

    def _act(self, action: Action) -> CraneError | None:
        """Do ``action`` to the crane; the error if the controller did not take it."""
        try:
            if action is Action.ENABLE:
                self.controller.restart()  # the first setpoint starts where the crane stands
                self.targets.forget()
                self.crane.enable()
            elif action is Action.DISABLE:
                self.crane.disable()
            elif action is Action.FREEZE_AND_DISABLE:
                self.controller.restart()
                if self.reading is not None:
                    self.crane.write_setpoint(self.reading.x_mm, self.reading.y_mm)
                    self.targets.wrote(self.reading.x_mm, self.reading.y_mm)
                self.crane.disable()
            elif action is Action.RESET_FAULTS:
                self.crane.reset_faults()
        except CraneError as err:
            return err
        return None

    # --- the control tick ------------------------------------------------------------------

    def _tick(self, now_s: float, mono_s: float, reading: CraneReading) -> Step:
        """Measure and estimate always; drive the crane only while armed."""
        self._error = None
        if not self.reachable:
            log.info("crane controller reachable again")
            self.reachable = True
        frames: Sequence[Frame] = [] if self.controller.paired else self.frames.take_recent()
        step = self.controller.step(now_s, frames[0] if frames else None,
                                    np.array([reading.x_mm, reading.y_mm]), self.fix(),
                                    self._timing(mono_s), older=frames[1:])
        if self.armed:
            try:
                self.crane.write_setpoint(*step.setpoint)
                self.targets.wrote(*step.setpoint)
            except CraneError as err:
                self._error = self._unreachable(err)
        return step

    def _observe_frames(self, now_s: float, mono_s: float, reading: CraneReading) -> None:
        """The pictures that came since the last poll, into the controller as they come (its
        step then only decides), aiming at the crane's position after the next tick."""
        frames = self.frames.take_recent()
        if not frames:
            return
        tick = max(self.sync.next_tick_s or mono_s, mono_s)
        aim_s = self.controller.aim_s(now_s + (tick - mono_s), self._timing(tick))
        self.controller.observe(now_s, frames, np.array([reading.x_mm, reading.y_mm]),
                                self.fix(), aim_s)

    def _timing(self, mono_s: float) -> Timing | None:
        """The controller takes setpoints when it reports (one cycle); its report is
        ``report_age_s`` (commissioned) old when it comes, and older since."""
        next_report, last_report = self.sync.next_report_s(mono_s), self.sync.last_report_s
        if next_report is None or last_report is None:
            return None
        return Timing(next_report - mono_s,
                      self.settings.report_age_s + (mono_s - last_report))

    def _track(self, now_s: float, mono_s: float, read_s: float, reading: CraneReading
               ) -> None:
        """Learn the controller's cycle from its report, read at ``read_s``; keep the report
        with the time it was measured (its cycle less ``report_age_s``) for the frames'
        pairing."""
        xy = (reading.x_mm, reading.y_mm)
        changed = self.sync.observe(read_s, xy)
        published = self.sync.published_s(read_s, changed, 1 / self.settings.poll_hz)
        if published is not None:
            measured = now_s - (mono_s - published) - self.settings.report_age_s
            self.controller.track.add(measured, np.array(xy),
                                      np.array([reading.vx_mm_s, reading.vy_mm_s]))

    def _unreachable(self, err: CraneError) -> CraneError:
        self.controller.restart()  # the crane may have stopped meanwhile: start afresh
        if self.reachable:
            log.warning("%s", err)
        self.reachable = False
        return err
