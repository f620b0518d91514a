"""What commissioning measures on the crane that is there (pure: recorded series in, figures
out; ``stb gantry identify`` records them).

The crane's true position comes from the tracking camera looking at a marker that stands
still below it (eq. 5–8 turned round: the marker's pixel offset is the crane's displacement);
the controller's report, sampling counter and velocity come over Modbus. From them:

* sampling period — how often the controller takes a setpoint (its ``setpoints_taken``
  counter);
* dead time — from the controller taking a step setpoint to the crane starting to move;
  total reaction — from writing it to motion (half a sampling period more, on average);
* report age — how old the reported position is when the controller publishes it: the time
  shift that lays the reported positions onto the camera's;
* following — from the controller taking a setpoint to the crane following it, on a ramp:
  how long the crane trails the written ramp less half a sampling period (the dead time and
  the position loop's lag, and more where the acceleration limit shapes each step); the
  gantry's ``reaction_s``;
* top speed and acceleration — from long moves (the reported velocity's plateau; a
  constant-acceleration fit to the camera's positions as the crane sets off).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MOTION_MM = 2.0
"""Displacement that counts as moving (the camera's crane position is good to ~0.1 mm)."""


@dataclass(frozen=True)
class Series:
    """Times (s) and values, increasing in time."""

    t_s: np.ndarray
    values: np.ndarray

    def at(self, t_s: np.ndarray | float) -> np.ndarray:
        return np.interp(t_s, self.t_s, self.values)


@dataclass(frozen=True)
class Figure:
    """A measured quantity: its median and spread (interquartile range) over ``n``."""

    median: float
    spread: float
    n: int

    @classmethod
    def of(cls, samples: list[float] | np.ndarray) -> Figure:
        x = np.asarray(samples, dtype=float)
        if not len(x):
            return cls(float("nan"), float("nan"), 0)
        q1, q2, q3 = np.percentile(x, [25, 50, 75])
        return cls(float(q2), float(q3 - q1), len(x))


def sampling_period(taken_at: np.ndarray) -> Figure:
    """From the times the ``setpoints_taken`` counter went up."""
    return Figure.of(np.diff(np.sort(taken_at)))


@dataclass(frozen=True)
class SetOff:
    """How a move began: when the crane left its rest, and how hard it accelerated."""

    t_s: float
    accel_mm_s2: float


def set_off(camera: Series, written_s: float, until_s: float, top_speed_mm_s: float
            ) -> SetOff | None:
    """The start of the move written at ``written_s`` (the crane at rest then): from rest at
    constant acceleration, √|x − x0| grows linearly in time, so a line through the camera's
    positions while it speeds up (below 80 % of ``top_speed_mm_s`` and 40 % of the way) gives
    the start (where it crosses zero) and the acceleration (2 · slope²)."""
    t, x = camera.t_s, camera.values
    before = (t > written_s - 0.3) & (t <= written_s)
    after = np.flatnonzero((t > written_s) & (t <= until_s))
    if before.sum() < 2 or len(after) < 4:
        return None
    rest = float(np.median(x[before]))
    travel = np.abs(x[after] - rest)
    if travel.max() < 4 * MOTION_MM:
        return None
    speed = np.abs(np.gradient(x[after], t[after]))
    fast = np.flatnonzero((speed >= 0.8 * top_speed_mm_s) | (travel > 0.4 * travel.max()))
    use = after[:int(fast[0]) if len(fast) else len(after)]
    use = use[np.abs(x[use] - rest) > MOTION_MM / 2]
    if len(use) < 3:
        return None
    slope, intercept = np.polyfit(t[use], np.sqrt(np.abs(x[use] - rest)), 1)
    if slope <= 0:
        return None
    return SetOff(float(-intercept / slope), float(2 * slope ** 2))


def report_timing(reported: Series, camera: Series, speed: float, *, max_s: float = 1.0,
                  step_s: float = 0.002) -> tuple[float, float]:
    """The shift τ that best lays ``reported`` (position at publication) onto the camera's
    position τ earlier (both in the same units, over the camera's time span): the reports'
    age; and how much it varies from report to report: what is left of the reports' offset
    from the camera at τ (its standard deviation), over the ramp's ``speed`` (the camera's own
    noise included, so a little more than the controller's)."""
    t = reported.t_s
    best, best_cost = 0.0, np.inf
    for tau in np.arange(0.0, max_s, step_s):
        inside = (t - tau >= camera.t_s[0]) & (t - tau <= camera.t_s[-1])
        if inside.sum() < 5:
            continue
        offset = reported.values[inside] - camera.at(t[inside] - tau)
        cost = float(np.var(offset))  # the camera's zero is arbitrary: only the spread counts
        if cost < best_cost:
            best, best_cost = float(tau), cost
    return best, float(np.sqrt(best_cost)) / speed if np.isfinite(best_cost) else 0.0


def ramp_lag(camera: Series, ramp_s: tuple[float, float], start_mm: float, speed_mm_s: float,
             *, settle_s: float = 1.5) -> float | None:
    """How long the crane trails a setpoint ramp written continuously (from ``start_mm`` at
    ``speed_mm_s`` over ``ramp_s``), on average once it has caught up (``settle_s`` after the
    start): the wait until the controller samples a setpoint (half a period on average), its
    dead time and the position loop's lag."""
    t0, t1 = ramp_s
    inside = (camera.t_s >= t0 + settle_s) & (camera.t_s <= t1)
    if inside.sum() < 5:
        return None
    written = start_mm + speed_mm_s * (camera.t_s[inside] - t0)
    return float(np.mean((written - camera.values[inside]) / speed_mm_s))


def cycle_tick(taken: np.ndarray, period: float, now_s: float) -> float:
    """A time the controller took a setpoint, from when the poller saw its counter go up:
    each sighting is late (by part of a poll, and by whatever held the poller up on a busy
    machine), never early, so the earliest phase among the recent ones (``now_s`` if none)."""
    recent = taken[-12:]
    if not len(recent):
        return now_s
    last = recent[-1]
    return float(last + np.min((recent - last + period / 2) % period - period / 2))


def tick_after(taken: np.ndarray, period: float, t_s: float) -> float | None:
    """The controller's first tick after ``t_s``: on the grid of its ticks around then (the
    earliest phase among the sightings within a few periods, as ``cycle_tick``), not the
    first sighting after it, which a poller held up sees late."""
    near = taken[np.abs(taken - t_s) <= 6 * period]
    if not len(near):
        return None
    tick = cycle_tick(near, period, t_s)
    return float(tick + np.ceil((t_s - tick) / period) * period)
