"""A fixed camera that looks at the table and the arm.

Rendering uses PyBullet's software renderer so that images can be taken in DIRECT mode,
on machines without a display or GPU.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pybullet
from pybullet_utils.bullet_client import BulletClient

from lanrocli.sim.layout import Vec3


@dataclass(frozen=True)
class CameraPose:
    """Orbit camera parameters, as PyBullet's debug camera defines them (degrees, metres)."""

    target: Vec3 = (-0.2, 0.0, 0.2)
    distance: float = 1.3
    yaw: float = 60.0
    pitch: float = -30.0
    fov: float = 55.0
    near: float = 0.05
    far: float = 5.0


class Camera:
    """Renders one client's scene from a fixed pose; matrices are computed once per size."""

    def __init__(self, client: BulletClient, pose: CameraPose | None = None) -> None:
        pose = pose if pose is not None else CameraPose()
        self._client = client
        self._pose = pose
        self._view = tuple(
            pybullet.computeViewMatrixFromYawPitchRoll(
                cameraTargetPosition=pose.target,
                distance=pose.distance,
                yaw=pose.yaw,
                pitch=pose.pitch,
                roll=0.0,
                upAxisIndex=2,
            )
        )
        self._projections: dict[tuple[int, int], tuple[float, ...]] = {}

    @property
    def pose(self) -> CameraPose:
        return self._pose

    def _projection(self, width: int, height: int) -> tuple[float, ...]:
        key = (width, height)
        if key not in self._projections:
            self._projections[key] = tuple(
                pybullet.computeProjectionMatrixFOV(
                    fov=self._pose.fov,
                    aspect=width / height,
                    nearVal=self._pose.near,
                    farVal=self._pose.far,
                )
            )
        return self._projections[key]

    def render(self, width: int, height: int) -> npt.NDArray[np.uint8]:
        """RGB image of the scene as uint8 of shape (height, width, 3)."""
        if width <= 0 or height <= 0:
            raise ValueError(f"image size must be positive, got {width}x{height}")
        _, _, rgba, _, _ = self._client.getCameraImage(
            width=width,
            height=height,
            viewMatrix=self._view,
            projectionMatrix=self._projection(width, height),
            renderer=pybullet.ER_TINY_RENDERER,
            flags=pybullet.ER_NO_SEGMENTATION_MASK,
        )
        image = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)
        return np.ascontiguousarray(image[:, :, :3])
