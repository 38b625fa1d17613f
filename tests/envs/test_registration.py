"""The gymnasium ids: registered by ``import lanrocli`` alone, reachable from a fresh interpreter, once, with
the episode limit that ``gymnasium.make`` is asked for."""

from __future__ import annotations

import importlib
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest

import lanrocli
from lanrocli.envs.registration import ENTRY_POINT, ENV_IDS, register_envs
from lanrocli.envs.settings import PLAIN_LIMIT


def run_python(code: str) -> subprocess.CompletedProcess[str]:
    """``code`` in a fresh interpreter that turns every warning into an error."""
    return subprocess.run(
        [sys.executable, "-W", "error", "-c", code], capture_output=True, text=True, timeout=300, check=False
    )


def test_importing_the_package_registers_every_task_without_loading_torch_or_pybullet() -> None:
    result = run_python(
        "import sys, lanrocli, gymnasium as gym\n"
        "heavy = sorted(m for m in ('torch', 'pybullet', 'lanrocli.envs.env') if m in sys.modules)\n"
        "assert not heavy, heavy\n"
        f"print(sorted(gym.spec(i).id for i in {list(ENV_IDS.values())!r}))\n"
        "env = gym.make('lanro/Reach-v0')\n"
        "env.reset(seed=0)\n"
        "env.close()\n"
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == str(sorted(ENV_IDS.values()))


def test_a_fresh_interpreter_reaches_the_ids_through_the_package_name() -> None:
    result = run_python(
        "import sys, gymnasium as gym\n"
        "env = gym.make('lanrocli:lanro/Push-v0', objects=3, mode='colour_shape')\n"
        "obs, info = env.reset(seed=0)\n"
        "assert env.unwrapped.task.name == 'push' and len(info['objects']) == 3\n"
        "env.close()\n"
        "import lanrocli.envs\n"  # the environments' own package registers nothing twice
        "gym.make('lanro/Grasp-v0').close()\n"
    )
    assert result.returncode == 0, result.stderr


def test_registering_again_changes_nothing_and_warns_nothing() -> None:
    specs = {env_id: gym.spec(env_id) for env_id in ENV_IDS.values()}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        register_envs()
        importlib.reload(lanrocli)
    for task, env_id in ENV_IDS.items():
        assert gym.spec(env_id) is specs[env_id]
        assert specs[env_id].entry_point == ENTRY_POINT and specs[env_id].kwargs == {"task": task, "time_limit": False}


def steps_until_truncated(env: gym.Env) -> int:
    """Steps of one episode in which the arm holds still, which never succeeds: it ends at the limit."""
    env.reset(seed=0)
    hold = np.zeros(env.action_space.shape, dtype=np.float32)
    for step in range(1, 10 * PLAIN_LIMIT):
        _, _, terminated, truncated, _ = env.step(hold)
        assert not terminated
        if truncated:
            return step
    raise AssertionError("the episode never ended")


@pytest.mark.parametrize("asked", [None, 7, PLAIN_LIMIT + 23])
def test_make_truncates_at_the_limit_asked_for_and_the_spec_says_which(asked: int | None) -> None:
    assert gym.spec("lanro/Reach-v0").max_episode_steps == PLAIN_LIMIT
    env = gym.make("lanro/Reach-v0", **({} if asked is None else {"max_episode_steps": asked}))
    try:
        expected = PLAIN_LIMIT if asked is None else asked
        assert env.spec is not None and env.spec.max_episode_steps == expected
        assert steps_until_truncated(env) == expected
    finally:
        env.close()
