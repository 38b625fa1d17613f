"""Collection: the actions stored, and its subprocesses."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from lanrocli.envs.env import LanroEnv
from lanrocli.envs.settings import EnvSettings
from lanrocli.train.collect import Collector, FinishedEpisode


def collect(settings: EnvSettings, episodes: int, envs: int = 1) -> list[FinishedEpisode]:
    """Whole episodes from ``envs`` environments (several run in subprocesses), the agent's actions all zeros."""
    collector = Collector(lambda: LanroEnv("reach", settings=settings), envs, "reach", seed=0)
    finished: list[FinishedEpisode] = []
    try:
        while len(finished) < episodes:
            collector.step_async(np.zeros((envs, 3), dtype=np.float32))
            finished += collector.step_wait()
    finally:
        collector.close()
    return finished


def test_the_agents_actions_are_stored() -> None:
    episodes = collect(EnvSettings(objects=2, correction_rate=1.0, max_episode_steps=5), 3)
    assert all(np.array_equal(e.data.actions, np.zeros_like(e.data.actions)) for e in episodes)


NEVER_CLOSED = """
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.settings import EnvSettings
from lanrocli.train.collect import Collector
collector = Collector(lambda: LanroEnv("reach", settings=EnvSettings()), 2, "reach", seed=0)
print("built", flush=True)
"""


def test_a_script_that_never_closes_its_collector_still_exits() -> None:
    """The collector's subprocesses ignore SIGTERM as evaluation workers do (``test_workers.py``)."""
    done = subprocess.run([sys.executable, "-c", NEVER_CLOSED], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "built\n"
