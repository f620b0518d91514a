"""When the gantry ticks: a fixed time after the crane controller publishes its position (pure).

The controller reports its position once per cycle (4 Hz), like a PLC's process image, and
takes the setpoint registers at the same moment. The gantry polls the report faster than the
cycle, notes when it changes, and puts its ticks ``offset_s`` after the report — whatever the
phase between its clock and the controller's. Which offset depends on how the picture is
paired with the crane's position:

* the paper's algorithms add the newest picture's offset to the report read at the tick
  (eq. 8): the older that report, the more of the crane's own last move shows up as robot
  motion — past ~0.15 s every one of them makes the crane chase itself (docs/experiments.md)
  — so they tick ``AFTER_REPORT_S`` after it;
* ``default`` pairs every picture with the crane's position when it was taken, so the report's
  age does not matter: it ticks ``WRITE_MARGIN_S`` before the controller takes the setpoint,
  with the freshest pictures, 0.125 s less behind the robot.

While the crane stands still the report does not change: the ticks keep the phase learnt
last, or run free at the period until one is learnt.

Each change lies between the poll that saw it and the one before: a bracket. Polls at a fixed
phase to the cycle (40 Hz against 4 Hz is exactly ten a cycle) would give the same bracket every
cycle and leave the phase a poll period uncertain, a bias fixed per run of up to half a poll
(12.5 ms: the live crane once followed 12 mm rms where the experiment, its polls on the
cycle, followed 10). So the polls are dithered (``dithered_period_s``) and the phase is the
middle of where the last few brackets overlap: within a few milliseconds after a second.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

AFTER_REPORT_S = 0.075
"""The paper's algorithms tick this long after the controller's report: then ~0.1 s old when
read, in the middle of the range where they do best (docs/experiments.md)."""
WRITE_MARGIN_S = 0.05
"""``default`` ticks this long before the controller takes the setpoint: a poll period (the
tick waits for the first poll after its time) and the Modbus write, with room to spare."""


def tick_offset_s(after_report_s: float | None, period_s: float, paired: bool) -> float:
    """The tick's offset after the report: the lab file's, else by how the picture is paired."""
    if after_report_s is not None:
        return after_report_s
    return period_s - WRITE_MARGIN_S if paired else AFTER_REPORT_S


POLL_DITHER = 0.5
"""Polls come a random 50–150 % of the poll period apart (the mean rate kept), so that
their brackets around a report's change differ from cycle to cycle."""


def dithered_period_s(period_s: float, u: float) -> float:
    """The wait until the next poll for ``u`` drawn uniformly from [0, 1)."""
    return period_s * (1 + POLL_DITHER * (2 * u - 1))


@dataclass
class CycleSync:
    """Learns the phase of the controller's reports from the times they changed and says when
    the next tick is due: ``offset_s`` after the next report."""

    period_s: float
    offset_s: float = AFTER_REPORT_S
    remembered: int = 8  # brackets intersected (the newest that overlap)
    _brackets: deque[tuple[float, float]] = field(init=False)
    _last_poll: tuple[float, tuple[float, float]] | None = None
    _next_tick_s: float | None = None
    _phase_s: float | None = None  # report_phase_s, worked out when the brackets change
    last_report_s: float | None = None
    """When the report last changed (between the two polls that saw it)."""

    def __post_init__(self) -> None:
        if not 0 <= self.offset_s < self.period_s:
            raise ValueError(f"offset_s {self.offset_s} must lie in [0, {self.period_s})")
        self._brackets = deque(maxlen=self.remembered)

    def observe(self, now_s: float, reported_xy: tuple[float, float]) -> bool:
        """One poll of the controller's reported position, read at ``now_s``; whether it
        changed since the last poll."""
        changed = self._last_poll is not None and reported_xy != self._last_poll[1]
        if changed:
            assert self._last_poll is not None
            if now_s - self._last_poll[0] < self.period_s:  # a longer gap says nothing
                self._brackets.append((self._last_poll[0], now_s))
                self._phase_s = self._phase_of_brackets()
            phase = self.report_phase_s
            self.last_report_s = 0.5 * (self._last_poll[0] + now_s) if phase is None else \
                self._in_cycle_of(phase, 0.5 * (self._last_poll[0] + now_s))
        self._last_poll = (now_s, reported_xy)
        return changed

    def published_s(self, now_s: float, changed: bool, margin_s: float) -> float | None:
        """When the controller published the report read at ``now_s``: the cycle it changed
        in (``changed``), else the last cycle at least ``margin_s`` (a poll) before — a report
        that stays the same is published again each cycle. Before the phase is known (the
        crane has not moved yet) a period before: a report is never older than that."""
        phase = self.report_phase_s
        if phase is None:
            return self.last_report_s if changed else now_s - self.period_s
        if changed:
            assert self.last_report_s is not None
            return self._in_cycle_of(phase, self.last_report_s)
        return phase + math.floor((now_s - margin_s - phase) / self.period_s) * self.period_s

    @property
    def report_phase_s(self) -> float | None:
        """When in the period the controller reports (None until the crane has moved): the
        middle of the overlap of the newest brackets, newest first, as far back as they
        overlap (an older one that does not — a late read, the two clocks' drift — ends it)."""
        return self._phase_s

    def _phase_of_brackets(self) -> float | None:
        if not self._brackets:
            return None
        low, high = self._brackets[-1]
        for start, end in reversed(list(self._brackets)[:-1]):
            shift = round((low + high - start - end) / (2 * self.period_s)) * self.period_s
            new_low, new_high = max(low, start + shift), min(high, end + shift)
            if new_low > new_high:
                break
            low, high = new_low, new_high
        return (0.5 * (low + high)) % self.period_s

    def _in_cycle_of(self, phase: float, t_s: float) -> float:
        """The report time nearest ``t_s``."""
        return phase + round((t_s - phase) / self.period_s) * self.period_s

    def next_report_s(self, now_s: float) -> float | None:
        """When the controller reports (and takes setpoints) next after ``now_s``, or None
        before the phase is known."""
        phase = self.report_phase_s
        if phase is None:
            return None
        return phase + math.ceil((now_s - phase) / self.period_s + 1e-9) * self.period_s

    @property
    def next_tick_s(self) -> float | None:
        """When the next tick is due (None before the first)."""
        return self._next_tick_s

    def due(self, now_s: float) -> bool:
        """Whether to tick now; if so, the next tick is scheduled (never sooner than half a
        period, never later than one and a half)."""
        if self._next_tick_s is not None and now_s < self._next_tick_s:
            return False
        phase = self.report_phase_s
        if phase is None:
            base = now_s if self._next_tick_s is None else self._next_tick_s
            self._next_tick_s = max(base + self.period_s, now_s + 0.5 * self.period_s)
        else:
            target = phase + self.offset_s
            k = math.ceil((now_s + 0.5 * self.period_s - target) / self.period_s)
            self._next_tick_s = target + k * self.period_s
        return True
