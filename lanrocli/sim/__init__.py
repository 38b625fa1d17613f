"""The PyBullet world: table, Panda arm with end-effector control, objects, contacts, camera.

Nothing here knows about language, tasks or rewards.
"""

from lanrocli.sim.camera import Camera, CameraPose
from lanrocli.sim.layout import (
    CONTROL_DT,
    OBJECT_AREA,
    PHYSICS_HZ,
    ROBOT_BASE,
    SUBSTEPS,
    WORKSPACE,
    Box,
)
from lanrocli.sim.objects import (
    COLOURS,
    SHAPES,
    ObjectSet,
    ObjectStates,
    ShapeSpec,
    SimObject,
    resting_position,
)
from lanrocli.sim.panda import (
    EE_LINK,
    LEFT_FINGER_LINK,
    MAX_FINGER_WIDTH,
    MAX_STEP,
    RIGHT_FINGER_LINK,
    Contacts,
    Panda,
    RobotState,
    action_size,
)
from lanrocli.sim.world import World

__all__ = [
    "COLOURS",
    "CONTROL_DT",
    "EE_LINK",
    "LEFT_FINGER_LINK",
    "MAX_FINGER_WIDTH",
    "MAX_STEP",
    "OBJECT_AREA",
    "PHYSICS_HZ",
    "RIGHT_FINGER_LINK",
    "ROBOT_BASE",
    "SHAPES",
    "SUBSTEPS",
    "WORKSPACE",
    "Box",
    "Camera",
    "CameraPose",
    "Contacts",
    "ObjectSet",
    "ObjectStates",
    "Panda",
    "RobotState",
    "ShapeSpec",
    "SimObject",
    "World",
    "action_size",
    "resting_position",
]
