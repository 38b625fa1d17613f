"""Grasp: hold the named object off the table between both fingers."""

from __future__ import annotations

import numpy as np

from lanrocli.tasks.base import ALIGNED, HOVER, ArmView, OracleMemory, TaskDefinition, TaskView

OFF_TABLE = 0.01
"""A grasped object counts as held once it is this far (m) above where it started."""

BETWEEN_FINGERS = 0.03
"""Horizontal distance (m) between object centre and the end effector for 'between the fingers'."""

LIFT_TO = 0.16
"""Height (m) to which the oracle carries a grasped object."""

CLOSE_STEPS = 6
"""Control steps the oracle gives the fingers to close before lifting."""


def held(view: TaskView) -> np.ndarray:
    """Both fingers touch the object, it sits between them, and it is off the table."""
    horizontal = np.linalg.norm(view.positions[:, :2] - view.ee_position[:2], axis=1)
    raised = view.positions[:, 2] - view.start_positions[:, 2]
    return view.left_finger & view.right_finger & (horizontal < BETWEEN_FINGERS) & (raised > OFF_TABLE)


class Grasp(TaskDefinition):
    """Held: both fingers on the object, the object between them and off the table."""

    name = "grasp"
    gym_id = "lanro/Grasp-v0"
    verbs = ("grasp", "grip", "grab")
    paraphrase_verbs = ("seize", "clutch")
    gripper = True

    def achieved(self, view: TaskView) -> np.ndarray:
        return held(view)

    def oracle(self, view: ArmView, memory: OracleMemory) -> np.ndarray:
        """Hover, descend around the object, close, raise: each phase ends when the hand gets there."""
        ee, pos, top = view.ee_position, view.target_position, view.target_top
        if memory.phase == 0:  # hover above with open fingers (this also lets go of a wrong object)
            goal = np.array([pos[0], pos[1], top + HOVER])
            if np.linalg.norm(ee[:2] - pos[:2]) < ALIGNED and ee[2] > top + 0.02:
                memory.phase = 1
            return np.append(view.towards(goal), 1.0)
        if memory.phase == 1:  # descend around the object
            goal = np.array([pos[0], pos[1], pos[2]])
            if abs(ee[2] - pos[2]) < 0.008:
                memory.phase, memory.timer = 2, 0
            return np.append(view.towards(goal), 1.0)
        if memory.phase == 2:  # close
            memory.timer += 1
            if memory.timer >= CLOSE_STEPS:
                memory.phase = 3
            return np.append(view.towards(np.array([pos[0], pos[1], pos[2]])), -1.0)
        return np.append(view.towards(np.array([ee[0], ee[1], LIFT_TO])), -1.0)
