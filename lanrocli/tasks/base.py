"""What every task is made of: the views it reads and the class each task subclasses.

A task reads the world only through two views that the environment and the scripted policies build, so this
package needs neither pybullet nor the language package: the curriculum schema, the command line and the
gymnasium ids can list the tasks without loading a simulator.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

HOVER = 0.07
"""Height (m) above an object's top at which the oracle's hand travels between objects."""

ALIGNED = 0.012
"""Horizontal error (m) under which the oracle's hand counts as above its target."""

FALLEN = -0.05
"""An object whose centre is lower than this (m) has fallen off the table. The goal's fall ends the episode,
lost; another object's does not: the arm can still do what it was asked, and a correction episode whose
wrong object was pushed off while the instructor waited to speak is not lost for that."""


@dataclass(frozen=True)
class TaskView:
    """What a success test reads after a step; arrays are per object in observation order."""

    left_finger: np.ndarray  # bool (n,) left finger touches the object
    right_finger: np.ndarray  # bool (n,)
    positions: np.ndarray  # (n, 3) m
    start_positions: np.ndarray  # (n, 3) m
    heights: np.ndarray  # (n,) full object height, m
    ee_position: np.ndarray  # (3,) m


@dataclass(frozen=True)
class ArmView:
    """What the scripted oracle reads in a state: where the hand and the objects are, how large each object
    is, which object it works on, and how far one action moves the hand. It is what any agent could be told,
    so the oracle stays a fair upper bound."""

    ee_position: np.ndarray  # (3,) m
    positions: np.ndarray  # (n, 3) m
    half_extents: np.ndarray  # (n, 3) m, at zero yaw
    target: int
    max_step: float  # m the hand moves for an action of 1

    @property
    def target_position(self) -> np.ndarray:
        return np.asarray(self.positions[self.target], dtype=np.float64)

    @property
    def target_top(self) -> float:
        return self.target_position[2] + self.half_extents[self.target][2]

    def radius(self, index: int) -> float:
        """The larger horizontal half size of object ``index``: how far from its centre the hand stays clear."""
        return float(max(self.half_extents[index][:2]))

    def towards(self, point: np.ndarray) -> np.ndarray:
        """The action that moves the hand straight at ``point``, at full speed until it is one step away."""
        return np.clip((point - self.ee_position) / self.max_step, -1.0, 1.0)


@dataclass
class OracleMemory:
    """What the oracle remembers while it works on one object; working on another starts a fresh one, so an
    oracle that followed a correction begins that object's task from its first phase."""

    phase: int = 0
    timer: int = 0
    plan: np.ndarray | None = None
    """A choice made once per object (push: the direction to push in)."""


class TaskDefinition:
    """One task, everything lanro knows of it in one class: its name (the curriculum's ``task``), its
    gymnasium id, its verbs, whether the arm uses its gripper, the parameters it draws per episode, its
    success test C_T (eq. 1) for every object at once, and the scripted oracle's action.

    The instructor uses the success test to notice work on a wrong object and the reward reads it for the
    goal, so the test is about each object alone. An instance lives as long as its environment; ``reset``
    redraws its parameters each episode.
    """

    name: ClassVar[str]
    gym_id: ClassVar[str]
    verbs: ClassVar[tuple[str, ...]]
    """The words the instructor may use for the task; the first is the one hints show."""
    paraphrase_verbs: ClassVar[tuple[str, ...]] = ()
    """Other words for the task that training never speaks: the paraphrase split's instructions use them
    (:mod:`lanrocli.language.paraphrase`). A task without any keeps its own verbs there."""
    gripper: ClassVar[bool] = False
    """Whether the arm uses its fingers: the action gains a fourth number, the finger opening."""
    threshold_range: ClassVar[tuple[float, float] | None] = None
    """Where a task draws one number per episode (how far to push, how high to lift), its range; the
    episode's draw is :attr:`threshold`."""

    def __init__(self) -> None:
        self.threshold = 0.0 if self.threshold_range is None else self.threshold_range[0]

    def reset(self, rng: np.random.Generator) -> None:
        """Draw this episode's :attr:`threshold`, where the task has a ``threshold_range``."""
        if self.threshold_range is not None:
            self.threshold = float(rng.uniform(*self.threshold_range))

    def achieved(self, view: TaskView) -> np.ndarray:
        """Per object, whether the task is done on it in this state."""
        raise NotImplementedError

    def oracle(self, view: ArmView, memory: OracleMemory) -> np.ndarray:
        """The scripted oracle's action for doing the task on ``view.target``."""
        raise NotImplementedError
