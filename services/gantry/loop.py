"""The gantry's control loop over any crane and any frame source (the live service's and the
experiments' alike).

Polled faster than the control period (``poll_hz``), it reads the crane controller's report,
lets ``CycleSync`` decide when to tick (a fixed time after the report), and on a tick hands
the newest frame and the reported position to the ``Controller`` and the setpoint to the crane.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from services.gantry.control import Controller, Step
from services.gantry.crane import Crane, CraneError, CraneReading
from services.gantry.cycle import CycleSync
from services.gantry.frames import FrameSource
from services.gantry.settings import GantrySettings

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Tick:
    """One control period's outcome: the report it read, what the controller did, or why the
    crane could not be driven (``error``; then ``step`` is None)."""

    now_s: float
    reading: CraneReading | None
    step: Step | None
    error: CraneError | None = None


class GantryLoop:
    def __init__(self, settings: GantrySettings, crane: Crane, frames: FrameSource,
                 controller: Controller) -> None:
        self.crane, self.frames, self.controller = crane, frames, controller
        self.sync = CycleSync(1 / settings.control_hz, settings.after_report_s)
        self.reachable = True

    def poll(self, now_s: float, monotonic_s: float | None = None) -> Tick | None:
        """Read the controller's report; tick when due. ``now_s`` is the frames' clock (their
        capture times), ``monotonic_s`` the scheduling clock (default: ``now_s``)."""
        mono = now_s if monotonic_s is None else monotonic_s
        try:
            reading = self.crane.read()
        except CraneError as err:
            return self._unreachable(now_s, err) if self.sync.due(mono) else None
        self.sync.observe(mono, (reading.x_mm, reading.y_mm))
        if not self.sync.due(mono):
            return None
        return self._tick(now_s, reading)

    def _tick(self, now_s: float, reading: CraneReading) -> Tick:
        try:
            if not reading.enabled:
                log.info("crane not enabled (faults %#x): enabling", reading.faults)
                self.controller.restart()
                self.crane.enable()
        except CraneError as err:
            return self._unreachable(now_s, err)
        if not self.reachable:
            log.info("crane controller reachable again")
            self.reachable = True
        step = self.controller.step(now_s, self.frames.take(),
                                    np.array([reading.x_mm, reading.y_mm]))
        try:
            self.crane.write_setpoint(*step.setpoint)
        except CraneError as err:
            return self._unreachable(now_s, err)
        return Tick(now_s, reading, step)

    def _unreachable(self, now_s: float, err: CraneError) -> Tick:
        self.controller.restart()  # the crane may have stopped meanwhile: start afresh
        if self.reachable:
            log.warning("%s", err)
        self.reachable = False
        return Tick(now_s, None, None, err)
