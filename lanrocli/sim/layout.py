"""Fixed geometry of the scene, in metres, in the world frame.

The world frame has its origin at the centre of the table top, x pointing away from the
robot, y to the robot's left and z up. Everything the environment layer samples (object
positions) and everything the controller clips (end-effector targets) is expressed here,
so the numbers live in one place.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Box:
    """An axis-aligned box; used for the object area and the end-effector workspace."""

    low: Vec3
    high: Vec3

    def clip(self, point: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Nearest point inside the box."""
        return np.clip(np.asarray(point, dtype=np.float64), self.low, self.high)

    def contains(self, point: npt.ArrayLike, tolerance: float = 0.0) -> bool:
        """Whether ``point`` lies inside the box grown by ``tolerance`` on every side."""
        p = np.asarray(point, dtype=np.float64)
        return bool(np.all(p >= np.asarray(self.low) - tolerance) and np.all(p <= np.asarray(self.high) + tolerance))


PHYSICS_HZ = 500
"""Physics rate (Hz); steps this small keep finger-object contacts stable in grasps."""

SUBSTEPS = 20
"""Physics steps per control action."""

CONTROL_DT = SUBSTEPS / PHYSICS_HZ
"""Seconds of simulated time per control action (0.04 s, i.e. 25 Hz)."""

SOLVER_ITERATIONS = 20
"""Constraint solver iterations per physics step (PyBullet's default is 50).

Faster than the default, with the same end-effector tracking and grasp success
(docs/performance.md).
"""

GRAVITY: Vec3 = (0.0, 0.0, -9.81)

TABLE_HALF_EXTENTS: Vec3 = (0.55, 0.40, 0.20)
"""Half size of the table box; long enough to carry the robot base at its back edge."""

TABLE_CENTRE: Vec3 = (-0.25, 0.0, -0.20)
"""Table box centre, chosen so that its top face is the plane z = 0."""

FLOOR_HEIGHT = TABLE_CENTRE[2] - TABLE_HALF_EXTENTS[2]
"""The floor at the table's foot, where an object pushed off the table comes to rest (m)."""

TABLE_LATERAL_FRICTION = 0.5
"""Bullet multiplies frictions; with objects at 1.0 pushed objects slide at mu = 0.5."""

ROBOT_BASE: Vec3 = (-0.5, 0.0, 0.0)
"""Panda base on the table top, 50 cm behind the centre of the object area.

The whole workspace is then reachable with the gripper pointing down; at 60 cm the far
corners were not.
"""

OBJECT_AREA = Box(low=(-0.15, -0.15, 0.0), high=(0.15, 0.15, 0.0))
"""Where object centres may be placed (30 x 30 cm on the table top)."""

WORKSPACE = Box(low=(-0.22, -0.22, 0.015), high=(0.22, 0.22, 0.20))
"""Clip box for the end-effector target (the point between the fingertips).

It covers the object area plus a 7 cm margin so objects at the border can be pushed
inwards; the floor keeps the fingertips (1.1 cm below the end-effector point) just above
the table top. The ceiling, 20 cm, leaves room for the highest lift (10 cm) and keeps random
exploration near the objects.
"""
