"""The gantry's algorithms by name (``[gantry] algorithm``): the paper's three (and our
Gaussian variant of its position filter, ``predict.py``) and ``default`` (``kalman.py``)."""

from __future__ import annotations

from typing import Literal

from common.names import ALGORITHMS, AlgorithmName
from services.gantry.kalman import FollowOptions, FollowPredictor
from services.gantry.predict import (
    Basic,
    ParticleFilter,
    ParticleOptions,
    Predictor,
)


def make_predictor(name: AlgorithmName, *, seed: int = 0,
                   particle: ParticleOptions = ParticleOptions(),
                   follow: FollowOptions = FollowOptions(),
                   max_horizon_s: float = 1.0) -> Predictor:
    def pf(output: Literal["position", "velocity"],
           model: Literal["linear", "gauss"]) -> ParticleFilter:
        return ParticleFilter(name, output, model, particles=particle.particles, seed=seed,
                              velocity_noise_mm_s=particle.velocity_noise_mm_s,
                              diff_max_mm=particle.diff_max_mm)

    if name == "basic":
        return Basic()
    if name == "pf-position":
        return pf("position", "linear")
    if name == "pf-position-gauss":
        return pf("position", "gauss")
    if name == "pf-velocity":
        return pf("velocity", "linear")
    if name == "default":
        return FollowPredictor(options=follow, max_horizon_s=max_horizon_s)
    raise ValueError(f"unknown algorithm {name!r}; choose one of {', '.join(ALGORITHMS)}")
