"""The paper's camera model (eq. 1–3) and a PTZ camera's picture in pixels (the AXIS 215's of
Table 1 by default), with the lens's distortion (OpenCV's model, ``common.lens``) where it was
measured.

Frames. The camera frame has its x axis along the optical axis, y to the image's right and z
to the image's bottom (so u grows with y and v with z, eq. 3). The pose ``T_world_camera``
maps camera coordinates into the world frame (eq. 1): ``X_world = R @ x_cam + t`` with
``R = Rx(rx) @ Ry(ry) @ Rz(rz)``. Millimetres and degrees at the interface, radians inside.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any, Protocol

import numpy as np

from common.lens import NO_DISTORTION, distort, undistort
from common.pose_fields import POSE_FIELDS, PoseFields
from common.volume import Box


def rot_x(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_xyz(rx_deg: float, ry_deg: float, rz_deg: float) -> np.ndarray:
    """R = Rx·Ry·Rz (paper eq. 1), angles in degrees."""
    rx, ry, rz = np.radians([rx_deg, ry_deg, rz_deg])
    return rot_x(rx) @ rot_y(ry) @ rot_z(rz)


def euler_xyz_deg(rotation: np.ndarray) -> tuple[float, float, float]:
    """Angles (rx, ry, rz) in degrees with R = Rx·Ry·Rz; ry in [-90°, 90°]."""
    r = np.asarray(rotation, dtype=float)
    ry = np.arcsin(np.clip(r[0, 2], -1.0, 1.0))
    if abs(r[0, 2]) < 1 - 1e-12:
        rx = np.arctan2(-r[1, 2], r[2, 2])
        rz = np.arctan2(-r[0, 1], r[0, 0])
    else:  # gimbal lock: only rx + rz (or rx - rz) is defined; put it all in rx
        rx = np.arctan2(r[2, 1], r[1, 1])
        rz = 0.0
    degrees = np.degrees([rx, ry, rz])
    return float(degrees[0]), float(degrees[1]), float(degrees[2])


def quaternion_wxyz(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """A rotation matrix as a unit quaternion (w, x, y, z) with w ≥ 0."""
    r = np.asarray(rotation, dtype=float)
    # The largest of the four |components| first, for accuracy (Shepperd's method).
    trace = float(np.trace(r))
    options = [trace, r[0, 0], r[1, 1], r[2, 2]]
    k = int(np.argmax(options))
    if k == 0:
        s = 2.0 * np.sqrt(max(1.0 + trace, 0.0))
        q = [s / 4, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        s = 2.0 * np.sqrt(max(1.0 + r[i, i] - r[j, j] - r[m, m], 0.0))
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (r[m, j] - r[j, m]) / s
        q[1 + i] = s / 4
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + m] = (r[m, i] + r[i, m]) / s
    quat = np.array(q) / np.linalg.norm(q)
    quat = -quat if quat[0] < 0 else quat
    w, x, y, z = (float(c) for c in np.clip(quat, -1.0, 1.0))
    return w, x, y, z


class PositionFields(Protocol):
    """Anything that names a point in the world with ``x_mm``, ``y_mm``, ``z_mm``."""

    @property
    def x_mm(self) -> float: ...
    @property
    def y_mm(self) -> float: ...
    @property
    def z_mm(self) -> float: ...


@dataclass(frozen=True)
class Pose:
    """T_world_camera: where a camera is (mm) and how it is turned (deg, R = Rx·Ry·Rz)."""

    x_mm: float
    y_mm: float
    z_mm: float
    rx_deg: float
    ry_deg: float
    rz_deg: float

    @cached_property
    def rotation(self) -> np.ndarray:
        return rotation_xyz(self.rx_deg, self.ry_deg, self.rz_deg)

    @cached_property
    def position(self) -> np.ndarray:
        return np.array([self.x_mm, self.y_mm, self.z_mm])

    @classmethod
    def of(cls, f: PoseFields) -> Pose:
        """The pose in a model's six pose fields (a CameraPose message, a sim camera's
        settings)."""
        return cls(*(getattr(f, name) for name in POSE_FIELDS))

    def fields(self) -> dict[str, Any]:  # Any: spread into a message's other fields
        """The six pose fields as keyword arguments (for a CameraPose message)."""
        return {name: getattr(self, name) for name in POSE_FIELDS}

    @classmethod
    def from_matrix(cls, rotation: np.ndarray, position: np.ndarray) -> Pose:
        rx, ry, rz = euler_xyz_deg(rotation)
        x, y, z = (float(v) for v in position)
        return cls(x, y, z, rx, ry, rz)

    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        """World points (N, 3) → camera frame (N, 3), eq. 2: x_cam = Rᵀ (X − t)."""
        return (np.asarray(points_world, dtype=float) - self.position) @ self.rotation

    def to_world(self, points_camera: np.ndarray) -> np.ndarray:
        return np.asarray(points_camera, dtype=float) @ self.rotation.T + self.position


PAL_PICTURES = ((704, 576), (352, 288), (176, 144))  # a 4:3 chip in PAL's pixel grid
NTSC_PICTURES = ((704, 480), (352, 240), (176, 120))  # … and in NTSC's


def picture_pixel_aspect(width_px: int, height_px: int) -> float:
    """The pixels' aspect of a picture of this size (their height over their width, as the
    focal lengths in pixels go: fv / fu): the analogue-TV sizes of a 4:3 chip have
    non-square pixels (PAL 12/11, NTSC 10/11: the AXIS 215's 704 × 576 picture of its
    3.6 × 2.7 mm chip); every other size has square ones (1920 × 1080, 1280 × 720, …)."""
    if (width_px, height_px) in PAL_PICTURES + NTSC_PICTURES:
        return height_px / width_px * 4 / 3
    return 1.0


@dataclass(frozen=True)
class Intrinsics:
    """A camera's picture in pixels (OpenCV's camera matrix; no chip size needed): the focal
    length along the picture's width in pixels, the picture's size, the pixels' aspect (the
    focal length along the height over that along the width; None: as the picture's size
    has it, ``picture_pixel_aspect``), the principal point (u, v; None: the picture's
    centre) and the lens's distortion (k1, k2, p1, p2, k3 on normalised coordinates; none by
    default)."""

    focal_px: float
    width_px: int = 704
    height_px: int = 576
    pixel_aspect: float | None = None
    principal_px: tuple[float, float] | None = None
    distortion: tuple[float, float, float, float, float] = NO_DISTORTION

    @classmethod
    def from_chip(cls, focal_mm: float, chip_mm: tuple[float, float], width_px: int,
                  height_px: int, **rest: Any) -> Intrinsics:
        """A camera from its data sheet: focal length and chip size (mm), picture size."""
        return cls(focal_mm * width_px / chip_mm[0], width_px, height_px,
                   (height_px / chip_mm[1]) / (width_px / chip_mm[0]), **rest)

    @property
    def fy_px(self) -> float:
        """The focal length along the picture's width (u, the camera's y axis), pixels."""
        return self.focal_px

    @property
    def fz_px(self) -> float:
        """… along its height (v, the camera's z axis)."""
        aspect = self.pixel_aspect if self.pixel_aspect is not None else \
            picture_pixel_aspect(self.width_px, self.height_px)
        return self.focal_px * aspect

    @property
    def cy_px(self) -> float:
        return self.width_px / 2 if self.principal_px is None else self.principal_px[0]

    @property
    def cz_px(self) -> float:
        return self.height_px / 2 if self.principal_px is None else self.principal_px[1]

    def with_focal(self, focal_px: float) -> Intrinsics:
        return replace(self, focal_px=focal_px)

    def pinhole(self) -> Intrinsics:
        """The same camera without its lens's distortion."""
        return replace(self, distortion=NO_DISTORTION)


def project_camera(points_camera: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Camera-frame points (N, 3) → pixels (N, 2) by eq. 3, bent by the lens's distortion;
    rows with x ≤ 0 become NaN."""
    p = np.atleast_2d(np.asarray(points_camera, dtype=float))
    with np.errstate(divide="ignore", invalid="ignore"):
        normalised = np.column_stack([p[:, 1] / p[:, 0], p[:, 2] / p[:, 0]])
    ahead = p[:, 0] > 0
    if any(intr.distortion) and np.any(ahead):

        normalised[ahead] = distort(normalised[ahead], intr.distortion)
    uv = np.column_stack([intr.fy_px * normalised[:, 0] + intr.cy_px,
                          intr.fz_px * normalised[:, 1] + intr.cz_px])
    uv[~ahead] = np.nan
    return uv


def undistort_pixels(uv: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """Pixels (N, 2) of a camera with ``intr``'s distortion → where a pinhole camera with the
    same focal length would have seen them (what eq. 3's inverse, aiming, needs)."""
    uv = np.atleast_2d(np.asarray(uv, dtype=float))
    if not any(intr.distortion):
        return uv.copy()

    normalised = np.column_stack([(uv[:, 0] - intr.cy_px) / intr.fy_px,
                                  (uv[:, 1] - intr.cz_px) / intr.fz_px])
    straight = undistort(normalised, intr.distortion)
    return np.column_stack([intr.fy_px * straight[:, 0] + intr.cy_px,
                            intr.fz_px * straight[:, 1] + intr.cz_px])


def project(points_world: np.ndarray, pose: Pose, intr: Intrinsics) -> np.ndarray:
    """World points (N, 3) → pixels (N, 2) (eq. 2 then eq. 3); behind the camera → NaN."""
    return project_camera(pose.to_camera(points_world), intr)


def pose_distance(a: Pose, b: Pose) -> tuple[float, float]:
    """How far apart two poses are: position (mm) and the angle of the rotation between them
    (degrees) — what a calibration's accuracy is judged by."""
    position = float(np.linalg.norm(a.position - b.position))
    cos = (np.trace(a.rotation.T @ b.rotation) - 1) / 2
    return position, float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def head_pose(mount: Pose, pan_deg: float, tilt_deg: float) -> Pose:
    """A PTZ camera's pose at a pan and tilt: mount · Rz(pan) · Ry(tilt), where ``mount`` is
    its pose at pan = tilt = 0 (x optical axis, z down in the image: positive pan turns right,
    positive tilt turns up)."""
    rotation = mount.rotation @ rot_z(np.radians(pan_deg)) @ rot_y(np.radians(tilt_deg))
    return Pose.from_matrix(rotation, mount.position)


def mount_pose(head: Pose, pan_deg: float, tilt_deg: float) -> Pose:
    """Inverse of ``head_pose``: the pose at pan = tilt = 0 of a camera seen at pan and tilt
    (calibration may run at any fixed pan and tilt; the PTZ chain needs the mount)."""
    rotation = head.rotation @ rot_y(np.radians(-tilt_deg)) @ rot_z(np.radians(-pan_deg))
    return Pose.from_matrix(rotation, head.position)


def thin_lens_image_distance_mm(focal_mm: float, object_distance_mm: float) -> float:
    """Image distance b of a lens focused on an object at distance z: 1/b = 1/f − 1/z (eq. 5)."""
    if object_distance_mm <= focal_mm:
        raise ValueError(f"object at {object_distance_mm} mm is inside the focal length")
    return 1.0 / (1.0 / focal_mm - 1.0 / object_distance_mm)


def reprojection_px(pose: Pose, world_mm: np.ndarray, pixels: np.ndarray,
                    intr: Intrinsics) -> np.ndarray:
    """Pixel distance per passpoint (inf where a point is behind the camera)."""
    error = np.linalg.norm(project(world_mm, pose, intr) - pixels, axis=1)
    return np.where(np.isfinite(error), error, np.inf)


@dataclass(frozen=True)
class PtzLimits:
    """A PTZ head's travel, as the camera reports it for ``query=limits`` (degrees, zoom
    steps)."""

    min_pan: float = -170.0
    max_pan: float = 170.0
    min_tilt: float = -90.0
    max_tilt: float = 90.0
    min_zoom: int = 1
    max_zoom: int = 9999

    @cached_property
    def box(self) -> Box:
        return Box((self.min_pan, self.min_tilt, self.min_zoom),
                   (self.max_pan, self.max_tilt, self.max_zoom))

    def clamp(self, pan: float, tilt: float, zoom: float) -> tuple[float, float, float]:
        pan, tilt, zoom = self.box.clamp((pan, tilt, zoom))
        return pan, tilt, zoom
