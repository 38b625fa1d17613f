from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import numpy.typing as npt
import pytest

from lanrocli.sim import MAX_STEP, ObjectSet, Panda, World

DriveTo = Callable[..., int]


@pytest.fixture
def world() -> Iterator[World]:
    w = World()
    yield w
    w.close()


@pytest.fixture
def panda(world: World) -> Panda:
    return Panda(world, gripper=False)


@pytest.fixture
def gripper_panda(world: World) -> Panda:
    return Panda(world, gripper=True)


@pytest.fixture
def objects(world: World) -> ObjectSet:
    return ObjectSet(world)


def drive(
    world: World,
    robot: Panda,
    target: npt.ArrayLike,
    grip: float = -1.0,
    tolerance: float = 0.004,
    max_steps: int = 40,
) -> int:
    """Proportional controller over normal actions; returns the steps it took."""
    goal = np.asarray(target, dtype=np.float64)
    for step in range(max_steps):
        move = np.clip((goal - robot.state().ee_position) / MAX_STEP, -1.0, 1.0)
        action = [*move, grip] if robot.gripper else list(move)
        robot.apply_action(action)
        world.step()
        if np.linalg.norm(goal - robot.state().ee_position) < tolerance:
            return step + 1
    return max_steps


def hold(world: World, robot: Panda, steps: int, grip: float = -1.0) -> None:
    """Keep the end effector where it is for a few steps."""
    action = [0.0, 0.0, 0.0, grip] if robot.gripper else [0.0, 0.0, 0.0]
    for _ in range(steps):
        robot.apply_action(action)
        world.step()


@pytest.fixture
def drive_to() -> DriveTo:
    return drive


@pytest.fixture
def hold_still() -> Callable[..., None]:
    return hold
