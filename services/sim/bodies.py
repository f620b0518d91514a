"""6DOF rigid bodies as QTM measures them (pure): a body's markers in its own frame, where
they are in the world, and the pose QTM fits to the markers it sees.

The robot's body is its top marker (the body's origin, the point the paper tracks) and three
more markers 60 mm lower on its chassis; it turns with its heading (the direction it moves;
the crater's slope is not modelled: roll and pitch stay 0). The wand is an L of three markers
held level. QTM fits a body to the markers it identified in a frame (at least three); with
fewer the body is lost (NaN). The extra markers are small mocap markers that the PTZ and
tracking cameras' images do not show (they render the large top marker only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MIN_MARKERS = 3


@dataclass(frozen=True)
class BodyDefinition:
    name: str
    points_mm: np.ndarray  # (N, 3) in the body's frame; row 0 is the body's origin marker

    def marker_labels(self, origin_label: str) -> list[str]:
        """QTM's labels of the body's points: the origin's own label, then "<body> - k"."""
        return [origin_label] + [f"{self.name} - {k}" for k in range(2, len(self.points_mm) + 1)]


ROBOT_POINTS_MM = np.array([[0.0, 0.0, 0.0], [150.0, 0.0, -60.0], [-90.0, 100.0, -60.0],
                            [-90.0, -100.0, -60.0]])
WAND_POINTS_MM = np.array([[0.0, 0.0, 0.0], [250.0, 0.0, 0.0], [0.0, 150.0, 0.0]])


def heading_rad(velocity_mm_s: np.ndarray, ahead_mm: np.ndarray) -> float:
    """Where a body's x axis points: where it moves (its velocity, or when it stands, the way
    its path goes on: ``ahead_mm``; else along +x)."""
    for direction in (velocity_mm_s, ahead_mm):
        if float(np.hypot(direction[0], direction[1])) > 1e-3:
            return float(np.arctan2(direction[1], direction[0]))
    return 0.0


def place(points_mm: np.ndarray, position_mm: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """The body's points in the world for a pose."""
    return points_mm @ rotation.T + position_mm


def fit(points_mm: np.ndarray, measured_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The pose (position of the body's origin, world-from-body rotation) that best maps the
    body's points onto the measured ones (Kabsch); None when fewer than three were seen."""
    seen = np.all(np.isfinite(measured_mm), axis=1)
    if int(seen.sum()) < MIN_MARKERS:
        return None
    body, world = points_mm[seen], measured_mm[seen]
    body_c, world_c = body.mean(axis=0), world.mean(axis=0)
    u, _, vt = np.linalg.svd((body - body_c).T @ (world - world_c))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return world_c - rotation @ body_c, rotation
