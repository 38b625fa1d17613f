"""Objects on the table, built from a shape name and a colour name.

Collision and visual shapes are created once per world and reused, so an environment can
remove and re-spawn its two or three objects every episode at little cost.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
import pybullet

from lanrocli.sim.layout import Vec3
from lanrocli.sim.world import World

Rgba = tuple[float, float, float, float]

COLOURS: Mapping[str, Rgba] = MappingProxyType(
    {
        "red": (0.85, 0.10, 0.10, 1.0),
        "green": (0.10, 0.70, 0.15, 1.0),
        "blue": (0.10, 0.25, 0.90, 1.0),
        "yellow": (0.95, 0.85, 0.10, 1.0),
        "purple": (0.50, 0.15, 0.70, 1.0),
        "orange": (1.00, 0.50, 0.05, 1.0),
        "pink": (1.00, 0.55, 0.75, 1.0),
        "cyan": (0.10, 0.85, 0.90, 1.0),
        "brown": (0.50, 0.30, 0.12, 1.0),
    }
)
"""RGBA per colour name; the names are the colour words of the instruction grammar."""


@dataclass(frozen=True)
class ShapeSpec:
    """Geometry of one shape; ``half_extents`` is its axis-aligned half size at zero yaw."""

    geometry: int
    half_extents: Vec3

    @property
    def radius(self) -> float:
        """Radius of a cylinder (its x half extent)."""
        return self.half_extents[0]

    @property
    def height(self) -> float:
        return 2.0 * self.half_extents[2]


SHAPES: Mapping[str, ShapeSpec] = MappingProxyType(
    {
        "cube": ShapeSpec(pybullet.GEOM_BOX, (0.025, 0.025, 0.025)),
        "cuboid": ShapeSpec(pybullet.GEOM_BOX, (0.035, 0.0175, 0.0175)),
        "cylinder": ShapeSpec(pybullet.GEOM_CYLINDER, (0.025, 0.025, 0.025)),
    }
)
"""Shapes by name: a 5 cm cube, a 7 x 3.5 x 3.5 cm bar lying along its own x axis, and an
upright cylinder 5 cm across and 5 cm tall. The open finger pads are 7.1 cm apart along
world y, so every shape can be grasped from above at any yaw (the cuboid most easily
across its width, i.e. at zero yaw)."""

OBJECT_MASS = 0.1
"""Kilograms; light enough to push and lift quickly, heavy enough to rest stably."""

OBJECT_LATERAL_FRICTION = 1.0
OBJECT_SPINNING_FRICTION = 0.001
OBJECT_ROLLING_FRICTION = 0.0005

IDENTITY_QUATERNION: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class SimObject:
    """One spawned object: its PyBullet body and the properties it was built from."""

    body_id: int
    shape: str
    colour: str

    @property
    def half_extents(self) -> Vec3:
        """Half size in metres along the object's own x, y, z axes."""
        return SHAPES[self.shape].half_extents

    @property
    def height(self) -> float:
        """Full height in metres when standing upright."""
        return SHAPES[self.shape].height


class ObjectStates(NamedTuple):
    """States of all objects in spawn order, world frame, SI units; arrays are read-only.

    positions (N, 3) m, orientations (N, 4) quaternions x y z w, linear_velocities (N, 3)
    m/s, angular_velocities (N, 3) rad/s.
    """

    positions: npt.NDArray[np.float64]
    orientations: npt.NDArray[np.float64]
    linear_velocities: npt.NDArray[np.float64]
    angular_velocities: npt.NDArray[np.float64]


def resting_position(shape: str, x: float, y: float) -> npt.NDArray[np.float64]:
    """Centre of an upright object of ``shape`` standing on the table at (x, y)."""
    return np.array([x, y, SHAPES[shape].half_extents[2]], dtype=np.float64)


def _read_only(array: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    array.flags.writeable = False
    return array


class ObjectSet:
    """The objects currently in a world, in spawn order."""

    def __init__(self, world: World) -> None:
        self._world = world
        client = world.client
        self._client = client
        self._collision_shapes: dict[str, int] = {}
        self._visual_shapes: dict[tuple[str, str], int] = {}
        self._objects: list[SimObject] = []
        self._get_pose = client.getBasePositionAndOrientation
        self._get_velocity = client.getBaseVelocity
        self._reset_pose = client.resetBasePositionAndOrientation
        self._reset_velocity = client.resetBaseVelocity
        self._cache_revision = -1
        self._cache: ObjectStates | None = None

    @property
    def objects(self) -> tuple[SimObject, ...]:
        return tuple(self._objects)

    @property
    def body_ids(self) -> tuple[int, ...]:
        return tuple(o.body_id for o in self._objects)

    def __len__(self) -> int:
        return len(self._objects)

    def __getitem__(self, index: int) -> SimObject:
        return self._objects[index]

    def _collision_shape(self, shape: str) -> int:
        if shape not in self._collision_shapes:
            spec = SHAPES[shape]
            if spec.geometry == pybullet.GEOM_CYLINDER:
                uid = self._client.createCollisionShape(spec.geometry, radius=spec.radius, height=spec.height)
            else:
                uid = self._client.createCollisionShape(spec.geometry, halfExtents=spec.half_extents)
            self._collision_shapes[shape] = int(uid)
        return self._collision_shapes[shape]

    def _visual_shape(self, shape: str, colour: str) -> int:
        key = (shape, colour)
        if key not in self._visual_shapes:
            spec = SHAPES[shape]
            rgba = COLOURS[colour]
            if spec.geometry == pybullet.GEOM_CYLINDER:
                uid = self._client.createVisualShape(
                    spec.geometry, radius=spec.radius, length=spec.height, rgbaColor=rgba
                )
            else:
                uid = self._client.createVisualShape(spec.geometry, halfExtents=spec.half_extents, rgbaColor=rgba)
            self._visual_shapes[key] = int(uid)
        return self._visual_shapes[key]

    def spawn(
        self,
        shape: str,
        colour: str,
        position: npt.ArrayLike,
        orientation: npt.ArrayLike = IDENTITY_QUATERNION,
    ) -> SimObject:
        """Create an object at rest; ``position`` is its centre, ``orientation`` x y z w."""
        if shape not in SHAPES:
            raise ValueError(f"unknown shape {shape!r}; known: {sorted(SHAPES)}")
        if colour not in COLOURS:
            raise ValueError(f"unknown colour {colour!r}; known: {sorted(COLOURS)}")
        client = self._client
        body = int(
            client.createMultiBody(
                baseMass=OBJECT_MASS,
                baseCollisionShapeIndex=self._collision_shape(shape),
                baseVisualShapeIndex=self._visual_shape(shape, colour),
                basePosition=_vec(position, 3),
                baseOrientation=_vec(orientation, 4),
            )
        )
        client.changeDynamics(
            body,
            -1,
            lateralFriction=OBJECT_LATERAL_FRICTION,
            spinningFriction=OBJECT_SPINNING_FRICTION,
            rollingFriction=OBJECT_ROLLING_FRICTION,
        )
        obj = SimObject(body_id=body, shape=shape, colour=colour)
        self._objects.append(obj)
        self._world.invalidate()
        return obj

    def clear(self) -> None:
        """Remove every object from the world (shapes stay cached for the next spawn)."""
        for obj in self._objects:
            self._client.removeBody(obj.body_id)
        self._objects.clear()
        self._world.invalidate()

    def reset_pose(
        self,
        index: int,
        position: npt.ArrayLike,
        orientation: npt.ArrayLike = IDENTITY_QUATERNION,
    ) -> None:
        """Teleport object ``index`` to a pose and zero its velocity."""
        body = self._objects[index].body_id
        self._reset_pose(body, _vec(position, 3), _vec(orientation, 4))
        self._reset_velocity(body, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        self._world.invalidate()

    def reset_poses(self, positions: npt.ArrayLike, orientations: npt.ArrayLike | None = None) -> None:
        """Teleport all objects (rows in spawn order) and zero their velocities."""
        pos = np.asarray(positions, dtype=np.float64).reshape(len(self._objects), 3)
        if orientations is None:
            orn = np.tile(IDENTITY_QUATERNION, (len(self._objects), 1))
        else:
            orn = np.asarray(orientations, dtype=np.float64).reshape(len(self._objects), 4)
        for i in range(len(self._objects)):
            self.reset_pose(i, pos[i], orn[i])

    def states(self) -> ObjectStates:
        """Poses and velocities of all objects; re-read only after the world changed."""
        revision = self._world.revision
        if self._cache is not None and self._cache_revision == revision:
            return self._cache
        n = len(self._objects)
        flat = np.empty((n, 13), dtype=np.float64)
        get_pose = self._get_pose
        get_velocity = self._get_velocity
        for i, obj in enumerate(self._objects):
            position, orientation = get_pose(obj.body_id)
            linear, angular = get_velocity(obj.body_id)
            flat[i] = (*position, *orientation, *linear, *angular)
        self._cache = ObjectStates(
            positions=_read_only(flat[:, 0:3]),
            orientations=_read_only(flat[:, 3:7]),
            linear_velocities=_read_only(flat[:, 7:10]),
            angular_velocities=_read_only(flat[:, 10:13]),
        )
        self._cache_revision = revision
        return self._cache


def _vec(values: npt.ArrayLike, size: int) -> list[float]:
    flat = np.asarray(values, dtype=np.float64).reshape(-1)
    if flat.shape != (size,):
        raise ValueError(f"expected {size} numbers, got shape {np.shape(values)}")
    return flat.tolist()
