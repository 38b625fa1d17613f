"""Collection: the scripted recoveries a share of correction episodes is acted by, and its subprocesses."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from lanrocli.agent.settings import SACSettings
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.settings import EnvSettings
from lanrocli.train.collect import Collector, FinishedEpisode, TrainingEnv
from lanrocli.train.trainer import Trainer, TrainSettings


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


@pytest.mark.parametrize("envs", [1, 2])
def test_scripted_recoveries_store_the_scripted_actions_and_follow_the_correction(envs: int) -> None:
    episodes = collect(EnvSettings(objects=2, correction_rate=1.0, scripted_recovery=1.0), 4, envs)
    assert all(e.scripted for e in episodes)
    for episode in episodes:
        data = episode.data
        # The arm moved by the script, not by the zeros sent, and what is stored is what it was given.
        assert np.abs(data.actions).max() > 0.1
        # The script acts on a wrong object first: the instructor corrects it, extending the sentence.
        assert (data.next_instructions != data.instructions).any(axis=1).sum() == 1
    assert sum(e.success for e in episodes) >= 3


def test_without_scripted_recoveries_the_agents_actions_are_stored() -> None:
    episodes = collect(EnvSettings(objects=2, correction_rate=1.0, max_episode_steps=5), 3)
    assert not any(e.scripted for e in episodes)
    assert all(np.array_equal(e.data.actions, np.zeros_like(e.data.actions)) for e in episodes)


def test_scripted_recoveries_are_drawn_among_correction_episodes_at_their_share() -> None:
    env = TrainingEnv(LanroEnv("reach", settings=EnvSettings(objects=2, correction_rate=0.5, scripted_recovery=0.5)))
    drawn = []
    for seed in range(300):
        _, info = env.reset(seed=seed)
        drawn.append((info["correction_episode"], info["scripted"]))
    env.close()
    assert not any(scripted for correction, scripted in drawn if not correction)
    among = [scripted for correction, scripted in drawn if correction]
    assert 0.4 < np.mean(among) < 0.6 and len(among) > 100


def test_scripted_episodes_are_learned_from_but_not_the_agents_training_success() -> None:
    env = EnvSettings(objects=2, correction_rate=1.0, scripted_recovery=1.0, max_episode_steps=20)
    trainer = Trainer(TrainSettings(task="reach", env=env, learning_starts=10**6), SACSettings(batch_size=32))
    trainer.run(100)
    assert trainer._collector is not None
    unfinished = trainer._collector.partials()[0]["actions"].shape[0]
    trainer.close()
    assert trainer.progress.episodes >= 5 and trainer.buffer.size + unfinished == 100
    assert trainer.train_success is None


def test_losses_are_kept_per_step_through_a_checkpoints_unfinished_episodes() -> None:
    def reach() -> LanroEnv:
        return LanroEnv("reach", settings=EnvSettings(objects=2, max_episode_steps=30))

    collector = Collector(reach, 1, "reach", seed=3)
    rng = np.random.default_rng(3)
    for _ in range(12):  # random pushes, well into an episode
        collector.step_async(rng.uniform(-1.0, 1.0, (1, 3)).astype(np.float32))
        collector.step_wait()
    saved = collector.partials()
    collector.close()
    lost = saved[0]["lost"]
    assert lost.shape == saved[0]["achieved"].shape and lost.dtype == bool
    restored = Collector(reach, 1, "reach", seed=3)
    restored.restore_partials(saved)
    assert np.array_equal(restored.partials()[0]["lost"], lost)
    older = [{key: value for key, value in saved[0].items() if key != "lost"}]  # a checkpoint from before losses
    restored.restore_partials(older)
    assert not restored.partials()[0]["lost"].any() and restored.partials()[0]["lost"].shape == lost.shape
    restored.close()


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
