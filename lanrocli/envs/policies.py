"""Scripted policies: the upper bound a learned agent is compared with, and test and benchmark drivers.

They read only what any agent could be told: the observation (end-effector position) and ``info``
(goal index, object positions, whether a correction was spoken). ``oracle`` solves the task on the goal
object; ``mistaken`` first does the task on a wrong object and follows the correction once it is spoken;
``random`` samples actions.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from lanrocli.choices import Task
from lanrocli.envs.tasks import make_task
from lanrocli.language import ObjectProps
from lanrocli.sim import MAX_STEP, SHAPES

HOVER = 0.07
"""Height (m) above an object's top at which the hand travels between objects."""

ALIGNED = 0.012
"""Horizontal error (m) under which the hand counts as above its target."""

FINGERTIP_DROP = 0.011
"""How far (m) the closed fingertips reach below the end-effector point."""

PUSH_GAP = 0.035
"""Distance (m) behind an object's edge where a push starts."""

PUSH_HEIGHT = 0.02
"""Height (m) of the end effector above the table while pushing."""

LIFT_TO = 0.16
"""Height (m) to which a grasped object is carried."""

CLOSE_STEPS = 6
"""Control steps the fingers get to close before lifting."""


class Policy(Protocol):
    def reset(self, seed: int | None = None) -> None: ...

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray: ...


def _towards(ee: np.ndarray, target: np.ndarray) -> np.ndarray:
    return np.clip((target - ee) / MAX_STEP, -1.0, 1.0)


def _radius(shape: str) -> float:
    return float(max(SHAPES[shape].half_extents[:2]))


def _push_direction(target: int, positions: np.ndarray, objects: tuple[ObjectProps, ...]) -> np.ndarray:
    """The horizontal direction whose push path and approach point stay farthest from the other objects."""
    best, best_clearance = np.array([1.0, 0.0]), -np.inf
    start = positions[target, :2]
    for angle in np.linspace(0.0, 2 * np.pi, 16, endpoint=False):
        u = np.array([np.cos(angle), np.sin(angle)])
        path = start + np.outer(np.linspace(-0.09, 0.12, 12), u)
        clearance = np.inf
        for k in range(len(positions)):
            if k != target:
                gap = np.linalg.norm(path - positions[k, :2], axis=1).min() - _radius(objects[k].shape)
                clearance = min(clearance, gap)
        # Prefer pushes towards the middle of the table so the object stays reachable.
        clearance -= 0.2 * max(0.0, float(np.dot(start, u)))
        if clearance > best_clearance:
            best, best_clearance = u, clearance
    return best


@dataclass
class _Solver:
    """Does the task on one object, phase by phase; a new target object restarts it."""

    task: Task
    target: int = -1
    phase: int = 0
    timer: int = 0
    direction: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0]))

    def aim(self, target: int, info: dict[str, Any]) -> None:
        if target != self.target:
            self.target, self.phase, self.timer = target, 0, 0
            if self.task is Task.PUSH:
                self.direction = _push_direction(target, info["object_positions"], info["objects"])

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        ee = observation["observation"][:3].astype(np.float64)
        pos = np.asarray(info["object_positions"][self.target], dtype=np.float64)
        shape = info["objects"][self.target].shape
        top = pos[2] + SHAPES[shape].half_extents[2]
        if self.task is Task.REACH:
            return self._reach(ee, pos, top)
        if self.task is Task.PUSH:
            return self._push(ee, pos, shape)
        return self._grasp(ee, pos, top)

    def _reach(self, ee: np.ndarray, pos: np.ndarray, top: float) -> np.ndarray:
        if np.linalg.norm(ee[:2] - pos[:2]) > ALIGNED:
            travel = top + HOVER / 2
            if ee[2] < travel - 0.01:  # let go of whatever was touched, gently, before moving sideways
                return 0.25 * _towards(ee, np.array([ee[0], ee[1], travel]))
            return _towards(ee, np.array([pos[0], pos[1], travel]))
        # Fingertips sit FINGERTIP_DROP below the end effector: aim them a few millimetres into the top,
        # slowly, so the touch does not shove the object away.
        return 0.5 * _towards(ee, np.array([pos[0], pos[1], top + FINGERTIP_DROP - 0.004]))

    def _push(self, ee: np.ndarray, pos: np.ndarray, shape: str) -> np.ndarray:
        u = np.append(self.direction, 0.0)
        behind = pos - u * (_radius(shape) + PUSH_GAP)
        if self.phase == 0:  # travel above the start of the push
            goal = np.array([behind[0], behind[1], pos[2] + HOVER])
            if np.linalg.norm(ee[:2] - goal[:2]) < ALIGNED:
                self.phase = 1
            return _towards(ee, goal)
        if self.phase == 1:  # go down behind the object
            goal = np.array([behind[0], behind[1], PUSH_HEIGHT])
            if abs(ee[2] - PUSH_HEIGHT) < 0.01:
                self.phase = 2
            return _towards(ee, goal)
        goal = pos + u * 0.03
        goal[2] = PUSH_HEIGHT
        return _towards(ee, goal)

    def _grasp(self, ee: np.ndarray, pos: np.ndarray, top: float) -> np.ndarray:
        if self.phase == 0:  # hover above with open fingers (this also lets go of a wrong object)
            goal = np.array([pos[0], pos[1], top + HOVER])
            if np.linalg.norm(ee[:2] - pos[:2]) < ALIGNED and ee[2] > top + 0.02:
                self.phase = 1
            return np.append(_towards(ee, goal), 1.0)
        if self.phase == 1:  # descend around the object
            goal = np.array([pos[0], pos[1], pos[2]])
            if abs(ee[2] - pos[2]) < 0.008:
                self.phase, self.timer = 2, 0
            return np.append(_towards(ee, goal), 1.0)
        if self.phase == 2:  # close
            self.timer += 1
            if self.timer >= CLOSE_STEPS:
                self.phase = 3
            return np.append(_towards(ee, np.array([pos[0], pos[1], pos[2]])), -1.0)
        return np.append(_towards(ee, np.array([ee[0], ee[1], LIFT_TO])), -1.0)


class OraclePolicy:
    """Solves the task on ``info['goal_index']``, the object the instructor means."""

    def __init__(self, task: str) -> None:
        self._solver = _Solver(Task(task))

    def reset(self, seed: int | None = None) -> None:
        self._solver = _Solver(self._solver.task)

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        self._solver.aim(int(info["goal_index"]), info)
        return self._solver.act(observation, info)


class MistakenPolicy:
    """Works on a wrong object until the instructor speaks a correction, then on the goal."""

    def __init__(self, task: str) -> None:
        self._solver = _Solver(Task(task))
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
        self._solver.aim(target, info)
        return self._solver.act(observation, info)


class RandomPolicy:
    """Uniform random actions."""

    def __init__(self, task: str) -> None:
        self._size = make_task(task).action_size
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
