"""The four tasks, each the condition C_T of eq. 1 evaluated for every object on the table at once.

A task sees a :class:`TaskView` of the world after a step (contacts, positions, where the objects
started) and answers, per object, whether the task is done on it. The instructor uses the same answer
to notice work on a wrong object; the reward reads it for the goal object.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from lanrocli import choices
from lanrocli.sim import action_size

REACH_STILL = 0.025
"""Reach on an object counts only while that object is within this distance (m) of its start."""

PUSH_DISTANCE = (0.025, 0.075)
"""Range (m) of the per-episode horizontal distance a pushed object must travel."""

LIFT_HEIGHT = (0.0, 0.10)
"""Range (m) of the per-episode height a lifted object must be raised above its start."""

OFF_TABLE = 0.01
"""A grasped object counts as held once it is this far (m) above where it started."""

BETWEEN_FINGERS = 0.03
"""Horizontal distance (m) between object centre and the end effector for 'between the fingers'."""


@dataclass(frozen=True)
class TaskView:
    """What the task conditions read after a step; arrays are per object in observation order."""

    left_finger: np.ndarray  # bool (n,) left finger touches the object
    right_finger: np.ndarray  # bool (n,)
    positions: np.ndarray  # (n, 3) m
    start_positions: np.ndarray  # (n, 3) m
    heights: np.ndarray  # (n,) full object height, m
    ee_position: np.ndarray  # (3,) m


class TaskCondition:
    """A task as the environment checks it: whether the arm uses its gripper, per-episode parameters, and
    the condition C_T. Named apart from :class:`lanrocli.choices.Task`, the task's name, which it carries."""

    name: ClassVar[choices.Task]

    @property
    def gripper(self) -> bool:
        return self.name.gripper

    @property
    def action_size(self) -> int:
        return action_size(self.gripper)

    def reset(self, rng: np.random.Generator) -> None:
        """Sample this episode's parameters (distances, heights)."""

    def achieved(self, view: TaskView) -> np.ndarray:
        raise NotImplementedError


class Reach(TaskCondition):
    """A finger touches the object, and that object has not been knocked away.

    The condition is about that object alone, like every C_T of eq. 1: an object the arm knocked on its
    way elsewhere does not undo reaching the goal. (Requiring every object to stay put made each episode
    in which the arm left a touched wrong object by dragging it unwinnable, which is how most correction
    episodes were lost.)
    """

    name = choices.Task.REACH

    def achieved(self, view: TaskView) -> np.ndarray:
        moved = np.linalg.norm(view.positions - view.start_positions, axis=1)
        touch = view.left_finger | view.right_finger
        return touch & (moved <= REACH_STILL)


class Push(TaskCondition):
    """The object slid farther than this episode's distance, without being lifted or tipped over."""

    name = choices.Task.PUSH

    def __init__(self) -> None:
        self.distance = PUSH_DISTANCE[0]

    def reset(self, rng: np.random.Generator) -> None:
        self.distance = float(rng.uniform(*PUSH_DISTANCE))

    def achieved(self, view: TaskView) -> np.ndarray:
        delta = view.positions - view.start_positions
        slid = np.linalg.norm(delta[:, :2], axis=1) > self.distance
        return slid & (np.abs(delta[:, 2]) < view.heights)


def held(view: TaskView) -> np.ndarray:
    """Both fingers touch the object, it sits between them, and it is off the table."""
    horizontal = np.linalg.norm(view.positions[:, :2] - view.ee_position[:2], axis=1)
    raised = view.positions[:, 2] - view.start_positions[:, 2]
    return view.left_finger & view.right_finger & (horizontal < BETWEEN_FINGERS) & (raised > OFF_TABLE)


class Grasp(TaskCondition):
    name = choices.Task.GRASP

    def achieved(self, view: TaskView) -> np.ndarray:
        return held(view)


class Lift(TaskCondition):
    """Held, and raised above this episode's height."""

    name = choices.Task.LIFT

    def __init__(self) -> None:
        self.height = LIFT_HEIGHT[0]

    def reset(self, rng: np.random.Generator) -> None:
        self.height = float(rng.uniform(*LIFT_HEIGHT))

    def achieved(self, view: TaskView) -> np.ndarray:
        raised = view.positions[:, 2] - view.start_positions[:, 2]
        return held(view) & (raised > self.height)


TASK_CLASSES: dict[choices.Task, type[TaskCondition]] = {cls.name: cls for cls in (Reach, Push, Grasp, Lift)}


def make_task(name: str) -> TaskCondition:
    if name not in TASK_CLASSES:
        raise ValueError(f"task must be one of {[task.value for task in choices.Task]}, got {name!r}")
    return TASK_CLASSES[choices.Task(name)]()
