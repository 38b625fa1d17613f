"""A task defined here alone, as the recipe "add a task" in docs/architecture.md has it: one class with its
verb, its success test and its oracle, registered for the test and run through the environment."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from lanrocli.envs.env import LanroEnv
from lanrocli.envs.policies import make_policy
from lanrocli.language import TASKS, UNK_ID, grammar_vocabulary
from lanrocli.tasks import ArmView, OracleMemory, Task, TaskDefinition, TaskView, registered

ABOVE = (0.03, 0.08)
"""How far (m) above an object's top the hand must be to hover over it."""


class Hover(TaskDefinition):
    """The hand is still above the object, between 3 and 8 cm over its top."""

    name = "hover"
    gym_id = "lanro/Hover-v0"
    verbs = ("hover",)

    def achieved(self, view: TaskView) -> np.ndarray:
        horizontal = np.linalg.norm(view.positions[:, :2] - view.ee_position[:2], axis=1)
        over = view.ee_position[2] - (view.positions[:, 2] + view.heights / 2)
        return (horizontal < 0.01) & (over > ABOVE[0]) & (over < ABOVE[1])

    def oracle(self, view: ArmView, memory: OracleMemory) -> np.ndarray:
        x, y, _ = view.target_position
        return view.towards(np.array([x, y, view.target_top + sum(ABOVE) / 2]))


@pytest.fixture
def hover() -> Iterator[type[TaskDefinition]]:
    with registered(Hover) as task:
        yield task


def test_the_oracle_hovers_over_the_goal_of_every_episode(hover: type[TaskDefinition]) -> None:
    env = LanroEnv(hover.name, objects=3, mode="colour_shape")
    oracle = make_policy("oracle", hover.name)
    for seed in range(3):
        observation, info = env.reset(seed=seed)
        oracle.reset(seed=seed)
        assert info["instruction_text"].startswith("hover the ")
        assert UNK_ID not in observation["instruction"]  # the verb is a word of the vocabulary built meanwhile
        for _ in range(env.max_episode_steps or 0):
            observation, reward, terminated, truncated, info = env.step(oracle.act(observation, info))
            if terminated or truncated:
                break
        assert terminated and reward == 0.0 and info["achieved"].tolist().count(True) == 1
    env.close()


def test_a_correction_follows_the_task_done_on_a_wrong_object(hover: type[TaskDefinition]) -> None:
    env = LanroEnv(hover.name, objects=2, correction_rate=1.0, kinds=["wrong_object"])
    mistaken = make_policy("mistaken", hover.name)
    observation, info = env.reset(seed=4)
    mistaken.reset(seed=4)
    while True:
        observation, _, terminated, truncated, info = env.step(mistaken.act(observation, info))
        if terminated or truncated:
            break
    assert terminated and info["correction"] is not None


def test_the_task_is_gone_once_its_test_ends() -> None:
    with registered(Hover):
        assert TASKS[-1] == "hover" and "hover" in grammar_vocabulary()
    assert "hover" not in TASKS and "hover" not in grammar_vocabulary()
    assert "hover" not in {task.value for task in Task}  # the command line's choices are the built-in tasks
    with pytest.raises(ValueError, match="'reach', 'push', 'grasp', 'lift'"):
        LanroEnv("hover")
