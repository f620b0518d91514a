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

import math
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
    """Models of the robot from calm (a walk, whose sway the phasor takes) to agile (a turn, a
    start, a stop; a slide, whose speed comes in a burst), mixed by an IMM (Blom and
    Bar-Shalom): each position weighs the models by how well they predicted it. State per
    model: (4, 2) — position, velocity, sway re, sway im — for x and y.

    Each model runs at its steady state: frames come at a steady rate with a steady noise, so
    its gain and innovation variance are those its Riccati equation settles to (worked out
    once per frame interval, gait and noise, and kept). That leaves a few small products per
    frame (tens of microseconds) where a full covariance took ten times as long."""

    def __init__(self, options: FollowOptions = FollowOptions(), gait: GaitMeter | None = None
                 ) -> None:
        self.options = options
        self.gait = gait if gait is not None else GaitMeter()
        self.accels = np.array(options.accels_mm_s2, dtype=float)
        self.bursts = np.array(options.bursts_s, dtype=float)
        if self.bursts.shape != self.accels.shape:
            raise ValueError("one burst time per motion model")
        self.models = len(self.accels)
        self.x: np.ndarray | None = None  # (models, 4, axes)
        self.mu = np.full(self.models, 1 / self.models)
        self.t_s = 0.0
        self._steady: dict[tuple[float, float, float], _Steady] = {}

    def update(self, t_s: float, z: np.ndarray, noise_mm: float | None = None) -> None:
        """A position measured at ``t_s``, give or take ``noise_mm`` (default: the options')."""
        o = self.options
        if self.x is None or t_s <= self.t_s - 1e-9 or t_s - self.t_s > o.max_gap_s:
            self._start(t_s, z)
            return
        self.gait.add(t_s, z)
        dt = max(t_s - self.t_s, 1e-4)
        self.t_s = t_s
        m = self._model(dt, o.measurement_noise_mm if noise_mm is None else noise_mm)
        c = m.switch.T @ self.mu  # each model's chance before this position
        w = m.switch * self.mu[:, None] / c  # w[i, j]: from model i into model j
        x = m.F @ (w.T @ self.x.reshape(self.models, -1)).reshape(self.x.shape)
        y = z - x[:, 0] - x[:, 2]  # (models, axes): the innovation
        self.x = x + m.K[:, :, None] * y[:, None, :]
        log_l = -0.5 * (y * y).sum(axis=1) / m.S - np.log(m.S)
        mu = c * np.exp(log_l - log_l.max())
        self.mu = mu / mu.sum()

    def ahead(self, horizon_s: float) -> np.ndarray:
        """The position ``horizon_s`` after the last update: each model's, by its weight."""
        assert self.x is not None
        burst = self.bursts > 0
        lead = np.where(burst, self.bursts * -np.expm1(-horizon_s / np.where(burst, self.bursts,
                                                                              1.0)), horizon_s)
        angle = self.gait.omega_rad_s * horizon_s
        x = self.x
        moved = x[:, 0] + lead[:, None] * x[:, 1] + math.cos(angle) * x[:, 2] \
            - math.sin(angle) * x[:, 3]
        return self.mu @ moved

    @property
    def state(self) -> np.ndarray:
        """The models' states mixed by their weights (4, axes)."""
        assert self.x is not None
        return (self.mu @ self.x.reshape(self.models, -1)).reshape(self.x.shape[1:])

    def _model(self, dt: float, noise_mm: float) -> _Steady:
        """The models' steady state for frames ``dt`` apart with ``noise_mm``: kept by the
        interval, the gait and the noise (in steps of 2 %)."""
        key = (round(dt, 4), self.gait.omega_rad_s, round(math.log(max(noise_mm, 0.1)) * 50))
        found = self._steady.get(key)
        if found is None:
            if len(self._steady) > 256:
                self._steady.clear()
            found = self._steady[key] = _settle(dt, self.gait.omega_rad_s, noise_mm,
                                                self.accels, self.bursts, self.options)
        return found

    def _start(self, t_s: float, z: np.ndarray) -> None:
        self.x = np.zeros((self.models, 4, 2))
        self.x[:, 0] = z
        self.mu = np.full(self.models, 1 / self.models)
        self.t_s = t_s
        self.gait.reset()
        self.gait.add(t_s, z)


@dataclass(frozen=True)
class _Steady:
    switch: np.ndarray  # (models, models): chances of going from one model to another
    F: np.ndarray  # (models, 4, 4)
    K: np.ndarray  # (models, 4): the steady gains
    S: np.ndarray  # (models,): the steady innovation variances (mm²)


def _settle(dt: float, omega: float, noise_mm: float, accels: np.ndarray, bursts: np.ndarray,
            o: FollowOptions, rounds: int = 400) -> _Steady:
    """Each model's Riccati equation iterated to its steady state (until its gain stops
    changing)."""
    models = len(accels)
    stay = o.stay ** (dt / 0.25)
    switch = np.full((models, models), (1 - stay) / max(models - 1, 1))
    np.fill_diagonal(switch, stay)
    F = _transitions(dt, omega, bursts)
    sway = o.sway_drift_mm_s ** 2 * dt if omega > 0 else 0.0
    h = np.array([1.0, 0.0, 1.0, 0.0])
    K, S = np.zeros((models, 4)), np.zeros(models)
    for m, accel in enumerate(accels):
        q = accel ** 2
        Q = np.diag([0.0, 0.0, sway, sway])
        Q[:2, :2] = [[q * dt ** 3 / 3, q * dt ** 2 / 2], [q * dt ** 2 / 2, q * dt]]
        P = np.diag([noise_mm ** 2, 300.0 ** 2, 1.0, 1.0])
        for _ in range(rounds):
            P = F[m] @ P @ F[m].T + Q
            ph = P @ h
            S[m] = float(h @ ph) + noise_mm ** 2
            gain = ph / S[m]
            settled = np.allclose(gain, K[m], rtol=1e-5, atol=1e-9)
            K[m] = gain
            P = P - np.outer(gain, ph)
            if settled:
                break
    return _Steady(switch, F, K, S)


def _transitions(dt: float, omega: float, bursts: np.ndarray) -> np.ndarray:
    """Each model's transition over ``dt`` (models, 4, 4): the position on with its velocity
    (which a burst model loses with its time constant), the sway turned by ω·dt."""
    c, s = math.cos(omega * dt), math.sin(omega * dt)
    F = np.broadcast_to(np.array([[1.0, dt, 0, 0], [0, 1.0, 0, 0], [0, 0, c, -s],
                                  [0, 0, s, c]]), (len(bursts), 4, 4)).copy()
    burst = bursts > 0
    if burst.any():
        kept = np.exp(-dt / bursts[burst])
        F[burst, 0, 1] = bursts[burst] * (1 - kept)
        F[burst, 1, 1] = kept
    return F


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

    def aim(self, aim_s: float) -> Estimate | None:
        """The estimate for the crane to be where the robot will be at ``aim_s``, from the
        positions so far (None before the first)."""
        f = self._filter
        if f is None or f.x is None:
            return None
        x = f.state
        return Estimate(x[0] + x[2], x[1], f.ahead(min(aim_s - f.t_s, self.max_horizon_s)))
