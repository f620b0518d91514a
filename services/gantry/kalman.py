"""``default``'s predictor: where the robot will be when the crane gets there (pure, numpy).

Fed every tracking frame's robot position, each at the moment the frame was taken (the crane's
position paired to that moment, ``crane_track.py``), it keeps a Kalman filter of the robot's
motion per axis — position, velocity and, for a walking robot, the sway of its gait:

* position and velocity, moved on with constant velocity; ``accel_mm_s2`` of white
  acceleration noise lets the velocity change (a turn, a start, a stop, a slide);
* the gait's sway as a phasor (two states turning at the gait's angular frequency ω): the
  marker's sideways swing, predicted ahead at its own phase. ω is measured from the positions
  themselves (``gait.py``): the strongest oscillation between ``gait_hz`` bounds in the last
  seconds, if it stands out; without one the phasor is left at rest.

Both axes share one covariance (same model, same noise), so the filter costs a few 4 × 4
products per frame. The desired crane position is the filter's position ``horizon_s`` ahead
of the frame (velocity times horizon, the sway turned on by ω · horizon).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from services.gantry.gait import GaitMeter
from services.gantry.predict import Estimate


@dataclass(frozen=True)
class FollowOptions:
    """The filter's noises (``[gantry.default_filter]``)."""

    measurement_noise_mm: float = 3.0  # the detector's, and the crane's report at rest
    accels_mm_s2: tuple[float, ...] = (10.0, 100.0, 600.0)  # the models, calm to agile
    bursts_s: tuple[float, ...] = (0.0, 0.0, 0.25)  # how long each model's speed lasts (0: on)
    stay: float = 0.97  # per control period (0.25 s): a model stays in charge
    sway_drift_mm_s: float = 3.0  # how fast the sway's amplitude and phase may wander
    max_gap_s: float = 1.0


class FollowFilter:
    """Two models of the robot — calm (``calm_accel_mm_s2``: a walk, whose sway the phasor
    takes) and agile (a turn, a start, a stop, a slide) — mixed by an IMM (Blom and
    Bar-Shalom): each position weighs the models by how well they predicted it. State per
    model: (4, 2) — position, velocity, sway re, sway im — for x and y; covariance per model
    and axis."""

    def __init__(self, options: FollowOptions = FollowOptions(), gait: GaitMeter | None = None
                 ) -> None:
        self.options = options
        self.gait = gait if gait is not None else GaitMeter()
        self.accels = np.array(options.accels_mm_s2)
        self.bursts = np.array(options.bursts_s)
        if self.bursts.shape != self.accels.shape:
            raise ValueError("one burst time per motion model")
        self.models = len(self.accels)
        self.x: np.ndarray | None = None  # (models, 4, axes)
        self.P = np.zeros((self.models, 2, 4, 4))  # (models, axes, 4, 4)
        self.mu = np.full(self.models, 1 / self.models)
        self.t_s = 0.0

    def update(self, t_s: float, z: np.ndarray, noise_mm: float | None = None) -> None:
        """A position measured at ``t_s``, give or take ``noise_mm`` (default: the options')."""
        o = self.options
        if self.x is None or t_s <= self.t_s - 1e-9 or t_s - self.t_s > o.max_gap_s:
            self._start(t_s, z)
            return
        self.gait.add(t_s, z)
        dt = max(t_s - self.t_s, 1e-6)
        self.t_s = t_s
        c = self._mix(dt)
        F = self._transition(dt)  # (models, 4, 4)
        self.x = F @ self.x
        self.P = F[:, None] @ self.P @ F.transpose(0, 2, 1)[:, None] + self._noise(dt)[:, None]
        h = np.array([1.0, 0.0, 1.0, 0.0])
        ph = self.P @ h  # (models, axes, 4)
        S = ph @ h + (o.measurement_noise_mm if noise_mm is None else noise_mm) ** 2
        y = z - h @ self.x  # (models, axes)
        K = ph / S[..., None]
        self.x = self.x + np.einsum("mak,ma->mka", K, y)
        self.P = self.P - K[..., :, None] * ph[..., None, :]
        likelihood = np.exp(-0.5 * (y * y / S).sum(axis=1)) / (2 * np.pi * S.prod(axis=1))
        mu = likelihood * c
        total = float(mu.sum())
        self.mu = mu / total if total > 0 and np.isfinite(total) else \
            np.full(self.models, 1 / self.models)

    def ahead(self, horizon_s: float) -> np.ndarray:
        """The position ``horizon_s`` after the last update: each model's, by its weight."""
        assert self.x is not None
        moved = self._transition(horizon_s) @ self.x  # (models, 4, axes)
        return np.einsum("m,ma->a", self.mu, moved[:, 0] + moved[:, 2])

    @property
    def state(self) -> np.ndarray:
        """The models' states mixed by their weights (4, axes)."""
        assert self.x is not None
        return np.einsum("m,mka->ka", self.mu, self.x)

    def _mix(self, dt: float) -> np.ndarray:
        """The IMM's mixing: each model starts from the others' states by the chances of a
        switch within ``dt``; returns the chances of each model before the update."""
        assert self.x is not None
        stay = self.options.stay ** (dt / 0.25)
        switch = np.full((self.models, self.models), (1 - stay) / max(self.models - 1, 1))
        np.fill_diagonal(switch, stay)
        c = switch.T @ self.mu
        w = switch * self.mu[:, None] / c[None, :]  # w[i, j]: from model i into j
        mixed = np.einsum("ij,ika->jka", w, self.x)
        d = self.x[:, None] - mixed[None]  # (i, j, 4, axes)
        spread = np.einsum("ij,ijka,ijla->jakl", w, d, d)
        self.P = np.einsum("ij,iakl->jakl", w, self.P) + spread
        self.x = mixed
        return c

    def _start(self, t_s: float, z: np.ndarray) -> None:
        o = self.options
        self.x = np.zeros((self.models, 4, 2))
        self.x[:, 0] = z
        self.P = np.broadcast_to(np.diag([o.measurement_noise_mm ** 2, 300.0 ** 2, 1.0, 1.0]),
                                 (self.models, 2, 4, 4)).copy()
        self.mu = np.full(self.models, 1 / self.models)
        self.t_s = t_s
        self.gait.reset()
        self.gait.add(t_s, z)

    def _transition(self, dt: float) -> np.ndarray:
        """Each model's (models, 4, 4): position on with its velocity (which a burst model
        loses with its time constant), the sway turned by ω·dt."""
        angle = self.gait.omega_rad_s * dt
        c, s = np.cos(angle), np.sin(angle)
        F = np.broadcast_to(np.array([[1.0, dt, 0, 0], [0, 1.0, 0, 0], [0, 0, c, -s],
                                      [0, 0, s, c]]), (self.models, 4, 4)).copy()
        bursts = self.bursts > 0
        if bursts.any():
            kept = np.exp(-dt / self.bursts[bursts])
            F[bursts, 0, 1] = self.bursts[bursts] * (1 - kept)
            F[bursts, 1, 1] = kept
        return F

    def _noise(self, dt: float) -> np.ndarray:
        """Each model's process noise (models, 4, 4)."""
        sway = (self.options.sway_drift_mm_s ** 2 * dt) if self.gait.omega_rad_s > 0 else 0.0
        out = np.zeros((self.models, 4, 4))
        for m, accel in enumerate(self.accels):
            q = accel ** 2
            out[m, :2, :2] = [[q * dt ** 3 / 3, q * dt ** 2 / 2], [q * dt ** 2 / 2, q * dt]]
            out[m, 2, 2] = out[m, 3, 3] = sway
        return out


@dataclass
class FollowPredictor:
    """``default``: the ``Predictor`` over a ``FollowFilter``."""

    name: str = "default"
    options: FollowOptions = field(default_factory=FollowOptions)
    max_horizon_s: float = 1.0
    _filter: FollowFilter | None = None

    def update(self, t_s: float, measured: np.ndarray | None, horizon_s: float | None = None,
               noise_mm: float | None = None) -> Estimate | None:
        if measured is None:
            return None
        if self._filter is None:
            self._filter = FollowFilter(self.options)
        f = self._filter
        f.update(t_s, np.asarray(measured, dtype=float), noise_mm)
        horizon = min(0.0 if horizon_s is None else horizon_s, self.max_horizon_s)
        x = f.state
        return Estimate(x[0] + x[2], x[1], f.ahead(horizon))
