"""Where the crane shall go next (paper §3.2; pure, seeded).

A predictor is fed with the robot's measured (x, y) — or None when the marker is lost — and
returns the desired crane position, or None when it has nothing
trustworthy to say (the safety layer then holds the crane).

* ``basic`` — eq. 9–10: velocity from the last two measurements, one period ahead.
* ``pf-position`` / ``pf-position-gauss`` — the particle filter of eq. 11 with the linear
  (eq. 12) or a Gaussian perceptual model and systematic resampling; the desired position is
  the mean of the believed particle positions.
* ``pf-velocity`` — the same filter's weighted mean velocity in eq. 10.
* ``default`` — ours (``kalman.py``): every picture, each paired with the crane's position
  when it was taken, into an IMM of calm to agile motion with the walker's gait.

The paper's algorithms are fed as the paper feeds them: one position per control period, the
newest picture's offset added to the crane's latest report (eq. 8).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, Protocol, runtime_checkable

import numpy as np

from common.names import AlgorithmName


@dataclass(frozen=True)
class Estimate:
    position: np.ndarray  # (x, y) mm, filtered where the algorithm filters
    velocity: np.ndarray  # (vx, vy) mm/s
    desired: np.ndarray  # where the crane shall go


class Predictor(Protocol):
    """One of the gantry's algorithms: fed every measured position (None when the marker was
    not seen), it gives its estimate of where the crane should go."""

    @property
    def name(self) -> str:
        """The algorithm's name (``AlgorithmName``; the experiments' bound is ``oracle``)."""

    def update(self, t_s: float, measured: np.ndarray | None, horizon_s: float | None = None,
               noise_mm: float | None = None) -> Estimate | None:
        """The estimate after a frame taken at ``t_s``; ``horizon_s``: how far ahead of it the
        crane will act on this setpoint, ``noise_mm`` how far the position may be off (only
        ``default`` uses them)."""


@runtime_checkable
class Aiming(Protocol):
    """A predictor that can say at any moment where the crane should be for a later one (the
    step asks it afresh each period, new pictures or not)."""

    def aim(self, aim_s: float) -> Estimate | None: ...


@dataclass
class Basic:
    """Eq. 9–10."""

    name: AlgorithmName = "basic"
    _last: tuple[float, np.ndarray] | None = None

    def update(self, t_s: float, measured: np.ndarray | None, horizon_s: float | None = None,
               noise_mm: float | None = None) -> Estimate | None:
        if measured is None:
            self._last = None
            return None
        z = np.asarray(measured, dtype=float)
        if self._last is None or t_s <= self._last[0]:
            self._last = (t_s, z)
            return Estimate(z, np.zeros(2), z)
        dt = t_s - self._last[0]
        v = (z - self._last[1]) / dt  # eq. 9
        self._last = (t_s, z)
        return Estimate(z, v, z + v * dt)  # eq. 10


@dataclass
class ParticleFilter:
    """Eq. 11–12. Each particle is a position and its own velocity (eq. 11's v_i); moving it
    adds Gaussian noise to that velocity (v_n), which the particle keeps. Weighting by the
    distance to the measurement (eq. 12, or a Gaussian) and resampling keep the particles —
    and so the velocities — that predicted well: the weighted mean velocity is the filtered
    velocity of ``pf-velocity``, the mean of the moved particles the desired position of
    ``pf-position`` (docs/experiments.md: why this reading of eq. 11)."""

    name: AlgorithmName = "pf-position"
    output: Literal["position", "velocity"] = "position"
    model: Literal["linear", "gauss"] = "linear"
    particles: int = 500
    velocity_noise_mm_s: float = 40.0
    diff_max_mm: float = 300.0  # eq. 12
    gauss_sigma_mm: float = 60.0
    seed: int = 0
    _rng: np.random.Generator = field(init=False)
    _pos: np.ndarray | None = None
    _vel: np.ndarray | None = None
    _last: tuple[float, np.ndarray] | None = None

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.seed)

    def update(self, t_s: float, measured: np.ndarray | None, horizon_s: float | None = None,
               noise_mm: float | None = None) -> Estimate | None:
        if measured is None:
            self._pos = self._last = None
            return None
        z = np.asarray(measured, dtype=float)
        if self._pos is None or self._last is None or t_s <= self._last[0]:
            return self._start(t_s, z, np.zeros(2))
        assert self._vel is not None
        dt = t_s - self._last[0]
        v_measured = (z - self._last[1]) / dt  # eq. 9
        self._last = (t_s, z)
        weights = self._weights(np.hypot(*(self._pos - z).T))
        if weights is None:  # every belief is far off: start again from the measurement
            return self._start(t_s, z, v_measured)
        v_filtered = weights @ self._vel
        keep = systematic_resample(weights, self._rng)
        self._pos, self._vel = self._pos[keep], self._vel[keep]
        current = self._pos.mean(axis=0)
        self._vel = self._vel + self._rng.normal(0.0, self.velocity_noise_mm_s, self._vel.shape)
        self._pos = self._pos + self._vel * dt  # eq. 11
        if self.output == "velocity":
            return Estimate(z, v_filtered, z + v_filtered * dt)  # eq. 10
        return Estimate(current, v_filtered, self._pos.mean(axis=0))

    def _start(self, t_s: float, z: np.ndarray, velocity: np.ndarray) -> Estimate:
        self._pos = z + self._rng.normal(0.0, 1.0, (self.particles, 2))
        self._vel = velocity + self._rng.normal(0.0, self.velocity_noise_mm_s,
                                                (self.particles, 2))
        self._last = (t_s, z)
        return Estimate(z, velocity, z.copy())

    def _weights(self, distance: np.ndarray) -> np.ndarray | None:
        if self.model == "linear":
            w = np.maximum(self.diff_max_mm - distance, 0.0)  # eq. 12
        elif distance.min() > GAUSS_FAR_SIGMAS * self.gauss_sigma_mm:
            return None  # as the linear model's zero weights: no particle explains it
        else:
            w = np.exp(-0.5 * (distance / self.gauss_sigma_mm) ** 2)
        total = float(w.sum())
        return w / total if total > 0 and np.isfinite(total) else None


GAUSS_FAR_SIGMAS = 4.0
"""With the Gaussian model a measurement farther than this many σ from every particle starts
the filter again (the linear model's weights are all zero then). Without it the weights of a
cloud that has lost the robot are still normalised, and the cloud flies on with its own
velocities: on the locomotive with σ_v = 13.8 mm/s it left the track in a turn and took the
crane 3.2 m off."""


def systematic_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices of the particles drawn: one random offset, then evenly spaced (filterpy's
    algorithm, but on our seeded generator — filterpy draws from numpy's global one)."""
    n = len(weights)
    positions = (rng.random() + np.arange(n)) / n
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0
    return np.searchsorted(cumulative, positions)


@dataclass(frozen=True)
class ParticleOptions:
    """The paper's particle filters' own parameters (not given in the paper; the defaults are
    identified with the sim, docs/experiments.md)."""

    particles: int = 500
    velocity_noise_mm_s: float = 13.8
    diff_max_mm: float = 103.0
