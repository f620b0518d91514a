"""The crane's own frame against the world's (the motion capture's): where a crane PLC counts
from and which way (pure; the gantry's ``[gantry.crane]`` and the sim's ``[sim.crane]``).

A crane controller counts its axes from its own home corner, perhaps the other way round
along one of them, and its axes are never exactly parallel to the motion capture's. With
``F = diag(±1, ±1)`` (``flip_x``, ``flip_y``) and ``R`` the rotation by ``yaw_deg``::

    world = origin + R · F · crane          crane = F · Rᵀ · (world − origin)

``origin_mm`` is where the crane's zero is in the world, ``yaw_deg`` how far the crane's axes
(before any flip) are turned counter-clockwise from the world's. A flip is a counting
direction, not a rotation: a camera on the carriage is not mirrored by it. One flip with yaw
θ is the same map as the other flip with yaw θ + 180°; ``canonical`` picks the one with
|yaw| ≤ 90°.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import ArrayLike
from pydantic import BaseModel, ConfigDict, Field

from common.crane_registers import RegisterMap


class CraneFrame(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    origin_mm: tuple[float, float] = Field((0.0, 0.0), description="where the crane's zero is "
                                           "in the world (x, y, mm)")
    yaw_deg: float = Field(0.0, ge=-180, le=180, description="the crane's axes turned "
                           "counter-clockwise from the world's, degrees")
    flip_x: bool = Field(False, description="the crane counts x against the world's x (after "
                         "the yaw)")
    flip_y: bool = Field(False, description="the crane counts y against the world's y")

    def frame(self) -> CraneFrame:
        """Only the frame (of a settings model that adds more fields to it)."""
        return CraneFrame(**{name: getattr(self, name) for name in CraneFrame.model_fields})

    @property
    def rotation(self) -> np.ndarray:
        return _rotation(self.yaw_deg)

    @property
    def linear(self) -> np.ndarray:
        """R · F: a crane-frame vector (a velocity, an offset on the carriage) in the world."""
        return _linear(self.yaw_deg, self.flip_x, self.flip_y)

    @property
    def is_identity(self) -> bool:
        return self == CraneFrame()

    def to_world(self, xy_crane: ArrayLike) -> np.ndarray:
        """Crane coordinates (…, 2) in the world (mm)."""
        return _origin(self.origin_mm) + np.asarray(xy_crane, dtype=float) @ self.linear.T

    def to_crane(self, xy_world: ArrayLike) -> np.ndarray:
        """World coordinates (…, 2) as the crane counts them (mm)."""
        return (np.asarray(xy_world, dtype=float) - _origin(self.origin_mm)) @ self.linear

    def vector_to_world(self, v_crane: ArrayLike) -> np.ndarray:
        return np.asarray(v_crane, dtype=float) @ self.linear.T

    def vector_to_crane(self, v_world: ArrayLike) -> np.ndarray:
        return np.asarray(v_world, dtype=float) @ self.linear

    @classmethod
    def from_linear(cls, origin_mm: np.ndarray, linear: np.ndarray) -> CraneFrame:
        """The frame of an orthogonal map ``linear`` (R · F), in its canonical form."""
        flip = bool(np.linalg.det(linear) < 0)
        rotation = linear @ np.diag([1.0, -1.0]) if flip else linear
        yaw = math.degrees(math.atan2(rotation[1, 0], rotation[0, 0]))
        return cls(origin_mm=(float(origin_mm[0]), float(origin_mm[1])), yaw_deg=yaw,
                   flip_y=flip).canonical()

    def canonical(self) -> CraneFrame:
        """The same map with |yaw| ≤ 90°: a flip moved to the other axis, or both flips made a
        half turn, as needed."""
        yaw, fx, fy = self.yaw_deg, self.flip_x, self.flip_y
        if abs(yaw) > 90.0:
            yaw = yaw - 180.0 if yaw > 0 else yaw + 180.0
            fx, fy = not fx, not fy  # R(θ+180) = −R(θ) = R(θ)·diag(−1, −1)
        return CraneFrame(origin_mm=self.origin_mm, yaw_deg=yaw, flip_x=fx, flip_y=fy)


CRANE_COUNTS_IN_THE_WORLD = CraneFrame()
"""The ideal lab's frame: the crane counts in the world's coordinates."""


class CraneConnection(RegisterMap, CraneFrame):
    """``[gantry.crane]``: the controller's register map (``common.crane_registers``) and its
    frame: how its registers map onto the world's coordinates."""


# Worked out once per value, not kept on the model: pydantic's ``model_copy(update=…)`` copies
# a model's cached properties with it, and a frame copied with a new yaw kept the old rotation.
@functools.lru_cache(maxsize=64)
def _rotation(yaw_deg: float) -> np.ndarray:
    a = math.radians(yaw_deg)
    rotation = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    rotation.flags.writeable = False
    return rotation


@functools.lru_cache(maxsize=64)
def _linear(yaw_deg: float, flip_x: bool, flip_y: bool) -> np.ndarray:
    linear = _rotation(yaw_deg) @ np.diag([-1.0 if flip_x else 1.0, -1.0 if flip_y else 1.0])
    linear.flags.writeable = False
    return linear


@functools.lru_cache(maxsize=64)
def _origin(origin_mm: tuple[float, float]) -> np.ndarray:
    origin = np.array(origin_mm, dtype=float)
    origin.flags.writeable = False
    return origin
