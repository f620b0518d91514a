"""The robots of the scenarios, as marker trajectories over time (pure, seeded, no clock).

Each scenario is a ``Trajectory``: the robot marker's world position (mm) at any time ``t``
(seconds since the scenario started), sampled at 100 Hz and interpolated. The marker (19 mm,
paper §3.1) follows the surface height of the crater plus the height it is mounted at.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.sim.world import CraterMap

SAMPLE_HZ = 100.0
MARKER_DIAMETER_MM = 19.0
MARKER_HEIGHT_MM = {"locomotive": 80.0, "walker": 350.0, "slides": 350.0, "figure8": 80.0,
                    "stop-and-go": 80.0, "zigzag": 80.0, "wander": 80.0}
"""How high above the ground each scenario's robot carries its marker (what the gantry's
look-up needs): the walker's body high, a wheeled robot's low."""


@dataclass(frozen=True)
class Trajectory:
    name: str
    t_s: np.ndarray  # (N,) increasing
    xyz_mm: np.ndarray  # (N, 3)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1])

    def position(self, t_s: float) -> np.ndarray:
        """Marker position at ``t_s``; before the start the first, after the end the last."""
        t, n = self.t_s, len(self.t_s)
        if n > 1 and t_s > t[0] and t_s < t[-1]:
            guess = int((t_s - t[0]) / (t[-1] - t[0]) * (n - 1))  # exact on an even grid
            i = min(max(guess, 0), n - 2)
            if not t[i] <= t_s <= t[i + 1]:
                i = int(np.searchsorted(t, t_s, side="right")) - 1
            w = (t_s - t[i]) / (t[i + 1] - t[i])
            return self.xyz_mm[i] * (1.0 - w) + self.xyz_mm[i + 1] * w
        return self.xyz_mm[0 if n == 1 or t_s <= t[0] else -1].copy()

    def velocity(self, t_s: float, dt_s: float = 0.02) -> np.ndarray:
        return (self.position(t_s + dt_s / 2) - self.position(t_s - dt_s / 2)) / dt_s


# --- locomotive: the paper's model railway ----------------------------------------------------


@dataclass(frozen=True)
class Oval:
    """A model-railway oval: two straights along x joined by two half circles (mm)."""

    straight_mm: float = 1500.0
    radius_mm: float = 500.0
    centre_x_mm: float = 0.0
    centre_y_mm: float = 0.0

    @property
    def length_mm(self) -> float:
        return 2 * self.straight_mm + 2 * np.pi * self.radius_mm

    def point(self, s_mm: np.ndarray) -> np.ndarray:
        """Points (N, 2) at arc lengths ``s_mm`` from the start (middle of the lower straight)."""
        s = np.mod(s_mm, self.length_mm)
        half, r, straight = self.straight_mm / 2, self.radius_mm, self.straight_mm
        arc = np.pi * r
        out = np.empty((len(s), 2))
        # lower straight from the start, going +x
        seg = [half, half + arc, half + arc + straight, half + 2 * arc + straight]
        a = s < seg[0]
        out[a] = np.column_stack([s[a], np.full(a.sum(), -r)])
        b = (s >= seg[0]) & (s < seg[1])
        phi = (s[b] - seg[0]) / r - np.pi / 2
        out[b] = np.column_stack([half + r * np.cos(phi), r * np.sin(phi)])
        c = (s >= seg[1]) & (s < seg[2])
        out[c] = np.column_stack([half - (s[c] - seg[1]), np.full(c.sum(), r)])
        d = (s >= seg[2]) & (s < seg[3])
        phi = (s[d] - seg[2]) / r + np.pi / 2
        out[d] = np.column_stack([-half + r * np.cos(phi), r * np.sin(phi)])
        e = s >= seg[3]
        out[e] = np.column_stack([-half + (s[e] - seg[3]), np.full(e.sum(), -r)])
        return out + [self.centre_x_mm, self.centre_y_mm]


@dataclass(frozen=True)
class Railway:
    """The paper's model railway run: an oval, ``rounds`` rounds at ``speed_mm_s`` (the paper:
    five at ca. 29 cm/s), then a stop exactly at the start. The oval's shape is not in the
    paper: identified (docs/experiments.md)."""

    speed_mm_s: float = 290.0
    rounds: int = 5
    straight_mm: float = 446.0
    radius_mm: float = 969.0

    @property
    def oval(self) -> Oval:
        return Oval(self.straight_mm, self.radius_mm)


def locomotive(world: CraterMap, railway: Railway = Railway(), *, accel_mm_s2: float = 300.0,
               marker_height_mm: float = MARKER_HEIGHT_MM["locomotive"],
               start_delay_s: float = 2.0) -> Trajectory:
    """``rounds`` rounds of the oval, then a stop exactly at the start (paper §3.3)."""
    speed_mm_s = railway.speed_mm_s
    distance = railway.rounds * railway.oval.length_mm
    ramp_s = speed_mm_s / accel_mm_s2
    ramp_mm = 0.5 * accel_mm_s2 * ramp_s**2
    cruise_s = (distance - 2 * ramp_mm) / speed_mm_s
    total = start_delay_s + 2 * ramp_s + cruise_s + 2.0
    t = np.arange(0, total, 1 / SAMPLE_HZ)
    tm = np.clip(t - start_delay_s, 0, None)
    s = np.where(tm < ramp_s, 0.5 * accel_mm_s2 * tm**2,
                 np.where(tm < ramp_s + cruise_s, ramp_mm + speed_mm_s * (tm - ramp_s),
                          distance - 0.5 * accel_mm_s2
                          * np.clip(2 * ramp_s + cruise_s - tm, 0, None) ** 2))
    xy = railway.oval.point(s)
    z = world.height_at(xy[:, 0], xy[:, 1]) + marker_height_mm
    return Trajectory("locomotive", t, np.column_stack([xy, z]))


# --- walker: a slow legged robot on the slopes ------------------------------------------------


@dataclass(frozen=True)
class Walk:
    """How the walker moves (paper §3.3: "slower but in a more oscillating way", now and then
    sliding "a little faster downhill"). The paper gives no figures: identified
    (docs/experiments.md)."""

    speed_mm_s: float = 29.8
    step_hz: float = 1.3
    sway_mm: float = 11.0
    surge_mm: float = 0.5
    slide_per_s: float = 0.04
    slide_speed_mm_s: float = 331.0
    duration_s: float = 240.0


WAYPOINTS_MM = np.array([[0.0, -600.0], [300.0, 1200.0], [-200.0, 2100.0], [200.0, 1400.0],
                         [-400.0, 300.0], [500.0, -900.0], [0.0, -600.0]])
"""Up the crater wall and down again (y up the slope)."""


def walker(world: CraterMap, rng: np.random.Generator, walk: Walk = Walk(), *,
           bob_mm: float = 8.0, slide_mm: tuple[float, float] = (120.0, 300.0),
           steep_deg: float = 28.0, marker_height_mm: float = MARKER_HEIGHT_MM["walker"]
           ) -> Trajectory:
    """Walks up and down the crater wall; its marker sways sideways once per gait cycle and
    surges forward and back twice, and on steep ground it now and then slides downhill
    (faster than it walks), as in paper §3.3."""
    t = np.arange(0, walk.duration_s, 1 / SAMPLE_HZ)
    xy = _walk_path(world, rng, walk, len(t), slide_mm, steep_deg)
    phase = 2 * np.pi * walk.step_hz * t
    ahead = np.column_stack([np.gradient(xy[:, 0]), np.gradient(xy[:, 1])])
    norms = np.linalg.norm(ahead, axis=1, keepdims=True)
    ahead = np.divide(ahead, norms, out=np.zeros_like(ahead), where=norms > 1e-9)
    lateral = np.column_stack([-ahead[:, 1], ahead[:, 0]])
    swayed = (xy + lateral * (walk.sway_mm * np.sin(phase))[:, None]
              + ahead * (walk.surge_mm * np.sin(2 * phase))[:, None])
    z = (world.height_at(swayed[:, 0], swayed[:, 1]) + marker_height_mm
         + bob_mm * np.abs(np.sin(phase)))
    return Trajectory("walker", t, np.column_stack([swayed, z]))


def _walk_path(world: CraterMap, rng: np.random.Generator, walk: Walk, samples: int,
               slide_mm: tuple[float, float], steep_deg: float) -> np.ndarray:
    """The walker's path without its sway: waypoint to waypoint, slides on steep ground."""
    xy = np.empty((samples, 2))
    pos, target = WAYPOINTS_MM[0].copy(), 1
    slide_left, slide_dir, slide_speed = 0.0, np.zeros(2), 0.0
    dt = 1 / SAMPLE_HZ
    for i in range(samples):
        if slide_left > 0:
            step = min(slide_speed * dt, slide_left)
            pos += slide_dir * step
            slide_left -= step
        else:
            to_target = WAYPOINTS_MM[target] - pos
            dist = np.hypot(*to_target)
            if dist < 20:
                target = (target + 1) % len(WAYPOINTS_MM)
            else:
                pos += to_target / dist * walk.speed_mm_s * dt
            if rng.random() < walk.slide_per_s * dt and world.slope_at(*pos) > steep_deg:
                slide_dir = world.downhill(*pos)
                slide_left = rng.uniform(*slide_mm)
                slide_speed = walk.slide_speed_mm_s * rng.uniform(0.8, 1.2)
        xy[i] = pos
    return xy


# --- calibration: a marker carried through the cameras' view -----------------------------------


def wand_point(world: CraterMap, rng: np.random.Generator, *, region_mm: float = 1600.0,
               height_mm: tuple[float, float] = (200.0, 1400.0)) -> np.ndarray:
    """A point over the crater floor where the calibration wand may be held."""
    x, y = rng.uniform(-region_mm, region_mm, size=2)
    return np.array([x, y, float(world.height_at(x, y)) + rng.uniform(*height_mm)])


def calibration(world: CraterMap, rng: np.random.Generator, *, points: int = 150,
                region_mm: float = 1600.0, height_mm: tuple[float, float] = (200.0, 1400.0),
                speed_mm_s: float = 400.0, dwell_s: float = 1.5) -> Trajectory:
    """A marker on a pole, carried from point to point over the crater floor and held still
    at each for ``dwell_s`` (so that snapshots see it sharp): passpoint collection (§2.2)."""
    samples_t, samples = [0.0], []
    targets = np.array([wand_point(world, rng, region_mm=region_mm, height_mm=height_mm)
                        for _ in range(points)])
    samples.append(targets[0])
    t = 0.0
    for a, b in zip(targets[:-1], targets[1:], strict=True):
        t += dwell_s
        samples_t.append(t)
        samples.append(a)
        t += float(np.linalg.norm(b - a)) / speed_mm_s
        samples_t.append(t)
        samples.append(b)
    samples_t.append(t + dwell_s)
    samples.append(targets[-1])
    keys_t, keys_xyz = np.array(samples_t), np.array(samples)
    tt = np.arange(0, keys_t[-1], 1 / SAMPLE_HZ)
    xyz = np.column_stack([np.interp(tt, keys_t, keys_xyz[:, i]) for i in range(3)])
    return Trajectory("calibration", tt, xyz)


def parked(world: CraterMap, *, at_mm: tuple[float, float] = (0.0, 0.0),
           marker_height_mm: float = MARKER_HEIGHT_MM["locomotive"],
           duration_s: float = 3600.0) -> Trajectory:
    """The robot parked: its marker stands still (for commissioning the crane)."""
    z = float(world.height_at(*at_mm)) + marker_height_mm
    return Trajectory("parked", np.array([0.0, duration_s]),
                      np.array([[*at_mm, z], [*at_mm, z]]))


def railway_keep_clear(oval: Oval = Railway().oval, margin_mm: float = 350.0
                       ) -> tuple[tuple[float, float, float], ...]:
    """Discs along the railway where the crater generator puts no rocks."""
    pts = oval.point(np.linspace(0, oval.length_mm, 60, endpoint=False))
    return tuple((float(x), float(y), margin_mm) for x, y in pts)
