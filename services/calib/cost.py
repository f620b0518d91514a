"""The paper's fitness (§2.2): mean pixel deviation over all passpoints, with a penalty for
points behind the camera — evaluated for a whole population of candidate poses at once.

A candidate is ``(x, y, z, rx, ry, rz)`` in mm and degrees, R = Rx·Ry·Rz (eq. 1).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common.camera import Intrinsics

BEHIND_PENALTY_PX = 1.0e4
"""What a passpoint behind the camera (x ≤ 0 in camera coordinates) costs."""


def rotations(angles_deg: np.ndarray) -> np.ndarray:
    """R = Rx·Ry·Rz for each row of (P, 3) angles in degrees → (P, 3, 3)."""
    a = np.radians(np.atleast_2d(angles_deg))
    cx, cy, cz = np.cos(a).T
    sx, sy, sz = np.sin(a).T
    r = np.empty((len(a), 3, 3))
    r[:, 0, 0] = cy * cz
    r[:, 0, 1] = -cy * sz
    r[:, 0, 2] = sy
    r[:, 1, 0] = sx * sy * cz + cx * sz
    r[:, 1, 1] = -sx * sy * sz + cx * cz
    r[:, 1, 2] = -sx * cy
    r[:, 2, 0] = -cx * sy * cz + sx * sz
    r[:, 2, 1] = cx * sy * sz + sx * cz
    r[:, 2, 2] = cx * cy
    return r


def residuals_px(candidates: np.ndarray, world_mm: np.ndarray, pixels: np.ndarray,
                 intr: Intrinsics) -> np.ndarray:
    """Pixel distance of every passpoint for every candidate, (P, N); behind → the penalty."""
    c = np.atleast_2d(np.asarray(candidates, dtype=float))
    rel = world_mm[None, :, :] - c[:, None, 0:3]
    cam = np.einsum("pnj,pjk->pnk", rel, rotations(c[:, 3:6]))  # x_cam = Rᵀ (X − t)
    x = cam[..., 0]
    front = x > 0
    safe_x = np.where(front, x, 1.0)
    du = intr.fy_px * cam[..., 1] / safe_x + intr.cy_px - pixels[None, :, 0]
    dv = intr.fz_px * cam[..., 2] / safe_x + intr.cz_px - pixels[None, :, 1]
    return np.where(front, np.hypot(du, dv), BEHIND_PENALTY_PX)


@dataclass
class Fitness:
    """The cost for an optimiser: counts evaluations and keeps the best-so-far curve."""

    world_mm: np.ndarray
    pixels: np.ndarray
    intr: Intrinsics
    evaluations: int = 0
    history: list[tuple[int, float]] = field(default_factory=list)  # (evaluations, best)
    _best: float = np.inf

    def __call__(self, candidates: np.ndarray) -> np.ndarray:
        values = residuals_px(candidates, self.world_mm, self.pixels, self.intr).mean(axis=1)
        self.evaluations += len(values)
        self._best = min(self._best, float(values.min()))
        self.history.append((self.evaluations, self._best))
        return values

    def one(self, candidate: np.ndarray) -> float:
        return float(self(np.asarray(candidate)[None, :])[0])
