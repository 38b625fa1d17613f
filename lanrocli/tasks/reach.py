"""Reach: touch the named object without knocking it away."""

from __future__ import annotations

import numpy as np

from lanrocli.tasks.base import ALIGNED, HOVER, ArmView, OracleMemory, TaskDefinition, TaskView

REACH_STILL = 0.025
"""Reach on an object counts only while that object is within this distance (m) of its start."""

FINGERTIP_DROP = 0.011
"""How far (m) the closed fingertips reach below the end-effector point."""


class Reach(TaskDefinition):
    """A finger touches the object, and that object has not been knocked away.

    The condition is about that object alone, like every C_T of eq. 1: an object the arm knocked on its
    way elsewhere does not undo reaching the goal. (Requiring every object to stay put made each episode
    in which the arm left a touched wrong object by dragging it unwinnable, which is how most correction
    episodes were lost.)
    """

    name = "reach"
    gym_id = "lanro/Reach-v0"
    verbs = ("reach", "touch", "contact")
    paraphrase_verbs = ("tap", "approach")

    def achieved(self, view: TaskView) -> np.ndarray:
        touch = view.left_finger | view.right_finger
        return touch & ~_knocked(view)

    def oracle(self, view: ArmView, memory: OracleMemory) -> np.ndarray:
        ee, pos, top = view.ee_position, view.target_position, view.target_top
        if np.linalg.norm(ee[:2] - pos[:2]) > ALIGNED:
            travel = top + HOVER / 2
            if ee[2] < travel - 0.01:  # let go of whatever was touched, gently, before moving sideways
                return 0.25 * view.towards(np.array([ee[0], ee[1], travel]))
            return view.towards(np.array([pos[0], pos[1], travel]))
        # Fingertips sit FINGERTIP_DROP below the end effector: aim them a few millimetres into the top,
        # slowly, so the touch does not shove the object away.
        return 0.5 * view.towards(np.array([pos[0], pos[1], top + FINGERTIP_DROP - 0.004]))


def _knocked(view: TaskView) -> np.ndarray:
    """Per object, whether it lies farther than ``REACH_STILL`` from its start."""
    return np.linalg.norm(view.positions - view.start_positions, axis=1) > REACH_STILL
