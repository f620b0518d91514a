"""Lens distortion as OpenCV models it (Brown–Conrady: k1, k2, p1, p2, k3, in OpenCV's order and
meaning), on normalised image coordinates x = X/Z, y = Y/Z (pure; OpenCV does the arithmetic:
``cv2.projectPoints`` one way, ``cv2.undistortPoints`` the other)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

NO_DISTORTION = (0.0, 0.0, 0.0, 0.0, 0.0)
_UNDISTORT_ITERATIONS, _UNDISTORT_EPS = 40, 1e-12


def distort(xy: np.ndarray, distortion: Sequence[float]) -> np.ndarray:
    """Normalised coordinates (N, 2) as the lens bends them (N, 2)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if not any(distortion):
        return xy.copy()
    import cv2  # imported when a lens bends: a pinhole's users do without OpenCV

    rays = np.column_stack([xy, np.ones(len(xy))])
    out, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), np.eye(3),
                               np.asarray(distortion, dtype=np.float64))
    return out.reshape(-1, 2)


def undistort(xy_distorted: np.ndarray, distortion: Sequence[float]) -> np.ndarray:
    """Normalised coordinates (N, 2) as a pinhole without the lens's bending would see them."""
    xy = np.asarray(xy_distorted, dtype=np.float64).reshape(-1, 1, 2)
    if not any(distortion):
        return xy.reshape(-1, 2).copy()
    import cv2

    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, _UNDISTORT_ITERATIONS,
                _UNDISTORT_EPS)
    out = cv2.undistortPoints(xy, np.eye(3), np.asarray(distortion, dtype=np.float64),
                              R=None, P=None, criteria=criteria)
    return out.reshape(-1, 2)
