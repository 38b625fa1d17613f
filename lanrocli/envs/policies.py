"""Scripted policies: the upper bound a learned agent is compared with, and test and benchmark drivers.

They read only what any agent could be told: the observation (end-effector position) and ``info``
(goal index, object positions, whether a correction was spoken). ``oracle`` solves the task on the goal
object with the task's own oracle; ``mistaken`` first does the task on a wrong object and follows the
correction once it is spoken; ``random`` samples actions.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from lanrocli.sim import MAX_STEP, SHAPES, action_size
from lanrocli.tasks import ArmView, OracleMemory, TaskDefinition, make_task


class Policy(Protocol):
    def reset(self, seed: int | None = None) -> None: ...

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray: ...


def arm_view(observation: dict[str, np.ndarray], info: dict[str, Any], target: int) -> ArmView:
    """The state as the task's oracle reads it, working on object ``target``."""
    return ArmView(
        ee_position=observation["observation"][:3].astype(np.float64),
        positions=info["object_positions"],
        half_extents=np.array([SHAPES[obj.shape].half_extents for obj in info["objects"]]),
        target=target,
        max_step=MAX_STEP,
    )


@dataclass
class _Solver:
    """Does the task on one object through its oracle; a new target object starts the oracle afresh."""

    task: TaskDefinition
    target: int = -1
    memory: OracleMemory = field(default_factory=OracleMemory)

    def act(self, target: int, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        if target != self.target:
            self.target, self.memory = target, OracleMemory()
        return self.task.oracle(arm_view(observation, info, target), self.memory)


class OraclePolicy:
    """Solves the task on ``info['goal_index']``, the object the instructor means."""

    def __init__(self, task: str) -> None:
        self._solver = _Solver(make_task(task))

    def reset(self, seed: int | None = None) -> None:
        self._solver = _Solver(self._solver.task)

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        return self._solver.act(int(info["goal_index"]), observation, info)


class MistakenPolicy:
    """Works on a wrong object until the instructor speaks a correction, then on the goal."""

    def __init__(self, task: str) -> None:
        self._solver = _Solver(make_task(task))
        self._rng = np.random.default_rng()
        self._wrong: int | None = None

    def reset(self, seed: int | None = None) -> None:
        self._solver = _Solver(self._solver.task)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self._wrong = None

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        goal = int(info["goal_index"])
        if self._wrong is None:
            others = [k for k in range(len(info["objects"])) if k != goal]
            self._wrong = int(self._rng.choice(others))
        target = goal if info["correction"] is not None else self._wrong
        return self._solver.act(target, observation, info)


class RandomPolicy:
    """Uniform random actions."""

    def __init__(self, task: str) -> None:
        self._size = action_size(make_task(task).gripper)
        self._rng = np.random.default_rng()

    def reset(self, seed: int | None = None) -> None:
        if seed is not None:
            self._rng = np.random.default_rng(seed)

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        return self._rng.uniform(-1.0, 1.0, self._size).astype(np.float32)


SCRIPTED_POLICIES: dict[str, type[OraclePolicy] | type[MistakenPolicy] | type[RandomPolicy]] = {
    "oracle": OraclePolicy,
    "mistaken": MistakenPolicy,
    "random": RandomPolicy,
}


def make_policy(name: str, task: str) -> Policy:
    if name not in SCRIPTED_POLICIES:
        raise ValueError(f"policy must be one of {sorted(SCRIPTED_POLICIES)}, got {name!r}")
    return SCRIPTED_POLICIES[name](task)
