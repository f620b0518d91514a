"""The paper's derivative-free searches from a rough initial pose: CMA-ES (pycma) and the
Downhill Simplex it compares with (scipy's Nelder-Mead with a scaled initial simplex —
scipy's default simplex of 5 % per coordinate fails from the paper's start)."""

from __future__ import annotations

from typing import Literal

import numpy as np

from services.calib.cost import Fitness

SearchMethod = Literal["cmaes", "simplex"]

STEP = np.array([500.0, 500.0, 500.0, 20.0, 20.0, 20.0])
"""How far the start may be off: 0.5 m and 20° per coordinate (CMA stds, simplex steps)."""
TOLFUN_PX = 1e-3
MAX_EVALUATIONS = 20_000


def cmaes(fitness: Fitness, start: np.ndarray, seed: int, step: np.ndarray = STEP) -> np.ndarray:
    """Ask/tell CMA-ES, the population's cost evaluated at once; returns the best candidate."""
    import cma  # 1 s to import (it pulls in matplotlib): only when asked for

    options = {"CMA_stds": list(step), "tolfun": TOLFUN_PX, "seed": seed,
               "maxfevals": MAX_EVALUATIONS, "verbose": -9, "verb_log": 0, "verb_disp": 0}
    es = cma.CMAEvolutionStrategy(list(start), 1.0, options)
    while not es.stop():
        population = es.ask()
        es.tell(population, list(fitness(np.asarray(population))))
    return np.asarray(es.result.xbest, dtype=float)


def simplex(fitness: Fitness, start: np.ndarray, step: np.ndarray = STEP) -> np.ndarray:
    initial = np.vstack([start, start + np.diag(step)])
    from scipy.optimize import minimize  # 0.4 s to import: only for the simplex

    result = minimize(fitness.one, start, method="Nelder-Mead",
                      options={"initial_simplex": initial, "fatol": TOLFUN_PX, "xatol": 1e-3,
                               "maxfev": MAX_EVALUATIONS})
    return np.asarray(result.x, dtype=float)


def search(method: SearchMethod, fitness: Fitness, start: np.ndarray, seed: int,
           step: np.ndarray = STEP) -> np.ndarray:
    if method == "cmaes":
        return cmaes(fitness, start, seed, step)
    return simplex(fitness, start, step)
