"""More robots for the gantry to follow than the paper's two (pure, seeded, no clock).

The paper tried the crane on a model railway and a slow walker. A lab follows other robots
too, and a predictor tuned on two paths may only have learnt those two; these paths were fixed
before the gantry's predictor was tuned on any of them (docs/experiments.md):

* ``figure8`` — a wheeled rover on a figure eight across the crater floor (200 mm/s): turns
  both ways, a crossing, no straight;
* ``stop-and-go`` — a rover driving from one random point to the next (up to 250 mm/s,
  accelerating and braking at 250 mm/s²), stopping 2–5 s at each (sampling);
* ``zigzag`` — legs of 600 mm at 200 mm/s with sharp corners (its heading turns 90° at once);
* ``wander`` — a rover whose speed (40–300 mm/s) and turning drift at random, kept on the
  crater floor;
* ``slides`` — the walker on a loose slope: it slides downhill six times as often.

Each is a ``Trajectory`` of the marker (world mm over seconds, 100 Hz).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from services.sim.robots import MARKER_HEIGHT_MM, SAMPLE_HZ, Trajectory, Walk, walker
from services.sim.world import CraterMap

FLOOR_MM = 1300.0
"""The rovers stay within this of the crater's centre (the floor is 1500 mm across)."""
SLIDES_PER_S = 0.24
"""``slides``: chances a second of a slide on steep ground (the walker's identified 0.04 × 6)."""


def _on_ground(world: CraterMap, name: str, t: np.ndarray, xy: np.ndarray) -> Trajectory:
    z = world.height_at(xy[:, 0], xy[:, 1]) + MARKER_HEIGHT_MM[name]
    return Trajectory(name, t, np.column_stack([xy, z]))


def _along(points: np.ndarray, s_mm: np.ndarray) -> np.ndarray:
    """Points at arc lengths ``s_mm`` along a polyline (N, 2)."""
    lengths = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])
    s = np.clip(s_mm, 0.0, lengths[-1])
    return np.column_stack([np.interp(s, lengths, points[:, 0]),
                            np.interp(s, lengths, points[:, 1])])


def _ramp(length_mm: float, speed_mm_s: float, accel_mm_s2: float
          ) -> tuple[float, float, float]:
    """A drive of ``length_mm`` that speeds up at ``accel_mm_s2`` to ``speed_mm_s`` and brakes
    likewise: (its ramp's duration, its top speed, its whole duration)."""
    ramp_s = speed_mm_s / accel_mm_s2
    if accel_mm_s2 * ramp_s ** 2 > length_mm:  # too short to reach full speed
        ramp_s = float(np.sqrt(length_mm / accel_mm_s2))
        speed_mm_s = accel_mm_s2 * ramp_s
    cruise_s = (length_mm - accel_mm_s2 * ramp_s ** 2) / speed_mm_s
    return ramp_s, speed_mm_s, 2 * ramp_s + cruise_s


def _ramped(length_mm: float, speed_mm_s: float, accel_mm_s2: float,
            t: np.ndarray) -> np.ndarray:
    """Distance covered at ``t`` by that drive (``_ramp``)."""
    ramp_s, top, end_s = _ramp(length_mm, speed_mm_s, accel_mm_s2)
    ramp_mm = 0.5 * accel_mm_s2 * ramp_s ** 2
    return np.where(t < ramp_s, 0.5 * accel_mm_s2 * t ** 2,
                    np.where(t < end_s - ramp_s, ramp_mm + top * (t - ramp_s),
                             length_mm - 0.5 * accel_mm_s2 * np.clip(end_s - t, 0, None) ** 2))


def figure_eight(world: CraterMap, *, half_width_mm: float = 1200.0, speed_mm_s: float = 200.0,
                 laps: int = 3, start_delay_s: float = 2.0) -> Trajectory:
    """``laps`` times round a figure eight (Gerono's lemniscate), starting and stopping at
    its crossing."""
    theta = np.linspace(0.0, 2 * np.pi * laps, 20_000 * laps)
    curve = np.column_stack([half_width_mm * np.sin(theta),
                             half_width_mm * np.sin(theta) * np.cos(theta)])
    length = float(np.hypot(*np.diff(curve, axis=0).T).sum())
    duration = start_delay_s + length / speed_mm_s + 4.0
    t = np.arange(0.0, duration, 1 / SAMPLE_HZ)
    s = _ramped(length, speed_mm_s, 300.0, np.clip(t - start_delay_s, 0, None))
    return _on_ground(world, "figure8", t, _along(curve, s))


def stop_and_go(world: CraterMap, rng: np.random.Generator, *, duration_s: float = 180.0,
                speed_mm_s: float = 250.0, accel_mm_s2: float = 250.0,
                stop_s: tuple[float, float] = (2.0, 5.0)) -> Trajectory:
    """From a random point of the floor to the next, stopping a while at each."""
    t = np.arange(0.0, duration_s, 1 / SAMPLE_HZ)
    xy = np.empty((len(t), 2))
    here, start_s, i = np.zeros(2), 0.0, 0
    while i < len(t):
        there = _floor_point(rng, away_from=here)
        leg = float(np.hypot(*(there - here)))
        end_s = start_s + _ramp(leg, speed_mm_s, accel_mm_s2)[2] + rng.uniform(*stop_s)
        n = int(np.searchsorted(t, end_s)) - i
        s = np.clip(_ramped(leg, speed_mm_s, accel_mm_s2, t[i:i + n] - start_s), 0, leg)
        xy[i:i + n] = here + np.outer(s / leg, there - here)
        here, start_s, i = there, end_s, i + n
    return _on_ground(world, "stop-and-go", t, xy)


def zigzag(world: CraterMap, *, leg_mm: float = 600.0, speed_mm_s: float = 200.0,
           rounds: int = 3, start_delay_s: float = 2.0) -> Trajectory:
    """Across the floor and back in legs at ±45° to the way it goes: a 90° corner each
    ``leg_mm``, taken at full speed."""
    step = leg_mm / np.sqrt(2)
    corners = [np.array([-1100.0, 0.0])]
    for k in range(int(2200 / step)):
        corners.append(corners[-1] + [step, step if k % 2 == 0 else -step])
    there = np.array(corners)
    path = np.concatenate([there, there[::-1][1:]] * rounds)
    length = float(np.hypot(*np.diff(path, axis=0).T).sum())
    duration = start_delay_s + length / speed_mm_s + 4.0
    t = np.arange(0.0, duration, 1 / SAMPLE_HZ)
    s = np.clip((t - start_delay_s) * speed_mm_s, 0.0, length)
    return _on_ground(world, "zigzag", t, _along(path, s))


def wander(world: CraterMap, rng: np.random.Generator, *, duration_s: float = 180.0,
           speed_mm_s: tuple[float, float] = (40.0, 300.0), turn_rad_s: float = 0.6,
           drift_s: float = 2.0) -> Trajectory:
    """A rover whose speed and turn rate drift at random (each a first-order random process
    with time constant ``drift_s``), steering back towards the centre near the floor's edge."""
    t = np.arange(0.0, duration_s, 1 / SAMPLE_HZ)
    dt, decay = 1 / SAMPLE_HZ, np.exp(-1 / (SAMPLE_HZ * drift_s))
    kick = np.sqrt(1 - decay ** 2)
    low, high = speed_mm_s
    mid, spread = (low + high) / 2, (high - low) / 4
    xy = np.empty((len(t), 2))
    pos, heading, speed, turn = np.zeros(2), rng.uniform(0, 2 * np.pi), mid, 0.0
    for i in range(len(t)):
        speed = mid + (speed - mid) * decay + spread * kick * rng.normal()
        turn = turn * decay + turn_rad_s * kick * rng.normal()
        if np.hypot(*pos) > FLOOR_MM:  # turn back towards the centre
            home = np.arctan2(-pos[1], -pos[0])
            turn = 1.5 * np.sign(np.sin(home - heading))
        heading += turn * dt
        pos = pos + float(np.clip(speed, low, high)) * dt * np.array(
            [np.cos(heading), np.sin(heading)])
        xy[i] = pos
    return _on_ground(world, "wander", t, xy)


def sliding_walker(world: CraterMap, rng: np.random.Generator, walk: Walk = Walk()
                   ) -> Trajectory:
    """The walker on a loose slope: ``SLIDES_PER_S`` instead of its own slide rate."""
    path = walker(world, rng, replace(walk, slide_per_s=SLIDES_PER_S))
    return Trajectory("slides", path.t_s, path.xyz_mm)


def _floor_point(rng: np.random.Generator, away_from: np.ndarray,
                 at_least_mm: float = 500.0) -> np.ndarray:
    while True:
        r, a = FLOOR_MM * np.sqrt(rng.uniform()), rng.uniform(0, 2 * np.pi)
        point = np.array([r * np.cos(a), r * np.sin(a)])
        if np.hypot(*(point - away_from)) >= at_least_mm:
            return point
