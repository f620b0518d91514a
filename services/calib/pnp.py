"""Closed-form pose without a guess (OpenCV's SQPnP inside RANSAC) and Levenberg-Marquardt
refinement, in the paper's camera convention.

OpenCV's camera has z along the optical axis, x right, y down; ours has x along the optical
axis, y right, z down (eq. 3). So p_cv = P·p_cam with the cyclic permutation
P = [[0,1,0],[0,0,1],[1,0,0]], and with p_cv = R_cv·X + t_cv:  R = R_cvᵀ·P,  t = −R·Pᵀ·t_cv.
"""

from __future__ import annotations

import cv2
import numpy as np

from common.camera import Intrinsics, Pose, project, reprojection_px

TO_CV = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
RANSAC_ITERATIONS = 300
RANSAC_CONFIDENCE = 0.999


def camera_matrix(intr: Intrinsics) -> np.ndarray:
    return np.array([[intr.fy_px, 0.0, intr.cy_px], [0.0, intr.fz_px, intr.cz_px],
                     [0.0, 0.0, 1.0]])


def pose_from_cv(rvec: np.ndarray, tvec: np.ndarray) -> Pose:
    r_cv, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float))
    rotation = r_cv.T @ TO_CV
    return Pose.from_matrix(rotation, -rotation @ TO_CV.T @ np.asarray(tvec, dtype=float).ravel())


def pose_to_cv(pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    r_cv = TO_CV @ pose.rotation.T
    rvec, _ = cv2.Rodrigues(r_cv)
    return rvec.ravel(), -(r_cv @ pose.position)


def ransac_seed(world_mm: np.ndarray, pixels: np.ndarray, intr: Intrinsics,
                inlier_px: float, seed: int) -> tuple[Pose, np.ndarray] | None:
    """SQPnP on random minimal sets, keeping the pose most passpoints agree with.
    Returns (pose, inlier indices) or None if no consensus was found."""
    cv2.setRNGSeed(seed)
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(
        world_mm.astype(np.float64), pixels.astype(np.float64), camera_matrix(intr), None,
        iterationsCount=RANSAC_ITERATIONS, reprojectionError=float(inlier_px),
        confidence=RANSAC_CONFIDENCE, flags=cv2.SOLVEPNP_SQPNP)
    if not ok or inliers is None or len(inliers) < 6:
        return None
    return pose_from_cv(rvec, tvec), np.sort(inliers.ravel())


def refine_lm(pose: Pose, world_mm: np.ndarray, pixels: np.ndarray,
              intr: Intrinsics) -> Pose:
    """Least-squares reprojection refinement (OpenCV's solvePnPRefineLM)."""
    rvec, tvec = pose_to_cv(pose)
    rvec, tvec = cv2.solvePnPRefineLM(world_mm.astype(np.float64), pixels.astype(np.float64),
                                      camera_matrix(intr), None, rvec.reshape(3, 1).copy(),
                                      tvec.reshape(3, 1).copy())
    return pose_from_cv(rvec, tvec)


def robust_refine(pose: Pose, world_mm: np.ndarray, pixels: np.ndarray, intr: Intrinsics,
                  inlier_px: float, rounds: int = 3) -> tuple[Pose, np.ndarray]:
    """Refine on the inliers, re-classify every passpoint, and repeat until they settle."""
    inliers = np.flatnonzero(reprojection_px(pose, world_mm, pixels, intr) <= inlier_px)
    for _ in range(rounds):
        if len(inliers) < 6:
            break
        pose = refine_lm(pose, world_mm[inliers], pixels[inliers], intr)
        again = np.flatnonzero(reprojection_px(pose, world_mm, pixels, intr) <= inlier_px)
        if np.array_equal(again, inliers):
            break
        inliers = again
    return pose, inliers


def pose_std(pose: Pose, world_mm: np.ndarray, pixels: np.ndarray, intr: Intrinsics
             ) -> tuple[np.ndarray, np.ndarray]:
    """1-σ uncertainty of a fitted pose from the residual scatter and the geometry
    (σ² (JᵀJ)⁻¹): position (mm, world axes) and rotation (deg, about world axes). Large values
    mean the passpoints do not pin the pose down (too few, or bunched in a small volume)."""
    def residuals(delta: np.ndarray) -> np.ndarray:
        turn = cv2.Rodrigues(delta[:3])[0]
        moved = Pose.from_matrix(turn @ pose.rotation, pose.position + delta[3:])
        return (project(world_mm, moved, intr) - pixels).ravel()

    base = residuals(np.zeros(6))
    steps = np.array([1e-6, 1e-6, 1e-6, 1e-3, 1e-3, 1e-3])
    jacobian = np.column_stack([(residuals(np.eye(6)[i] * steps[i]) - base) / steps[i]
                                for i in range(6)])
    dof = max(base.size - 6, 1)
    try:
        covariance = (base @ base / dof) * np.linalg.inv(jacobian.T @ jacobian)
    except np.linalg.LinAlgError:
        return np.full(3, np.inf), np.full(3, np.inf)
    std = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    return std[3:], np.degrees(std[:3])
