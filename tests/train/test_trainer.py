"""Training end to end, resume equivalence, and checkpoints that survive kills and refuse pickles."""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from lanrocli.agent import SACSettings
from lanrocli.train import CheckpointError, Trainer, TrainSettings
from lanrocli.train.checkpoint import AGENT_FILE, LATEST, load_agent_state, read_pointer

SETTINGS = TrainSettings(
    task="push",
    env={"objects": 2, "correction_rate": 0.5},
    seed=3,
    envs=1,
    eval_every=130,
    eval_episodes=2,
    learning_starts=64,
)
AGENT = SACSettings(buffer_size=5000, batch_size=32)


def parameters(trainer: Trainer) -> list[torch.Tensor]:
    agent = trainer.agent
    return [p.detach().clone() for net in (agent.actor, agent.critic, agent.target_critic) for p in net.parameters()]


def test_tiny_training_run_end_to_end(tmp_path: Path) -> None:
    trainer = Trainer(SETTINGS, AGENT, tmp_path)
    before = parameters(trainer)
    assert trainer.run(300)
    assert trainer._collector is not None
    unfinished = trainer._collector.partials()[0]["actions"].shape[0]
    trainer.close()
    # Updates start once whole episodes hold learning_starts transitions, then one per step.
    assert trainer.progress.env_steps == 300 and 0 < trainer.progress.updates <= 300 - 64
    # Every step is either in a stored episode or in the episode still running.
    assert trainer.buffer.size + unfinished == 300
    assert any(not torch.equal(a, b) for a, b in zip(before, parameters(trainer)))
    rows = (tmp_path / "metrics.csv").read_text().splitlines()
    assert len(rows) == 1 + 2 and rows[0].startswith("env_steps,wall_time,success")
    latest = read_pointer(tmp_path / LATEST)
    assert latest.name == "step-0000000260" and latest.is_dir()


def test_resume_continues_exactly(tmp_path: Path) -> None:
    straight = Trainer(SETTINGS, AGENT, tmp_path / "straight")
    straight.run(300)
    straight.close()

    first = Trainer(SETTINGS, AGENT, tmp_path / "split")
    first.run(150)  # stops mid-episode: push episodes with corrections last up to 100 steps
    first.checkpoint()
    first.close()
    resumed = Trainer.resume(tmp_path / "split")
    assert resumed.progress.env_steps == 150
    resumed.run(300)
    resumed.close()

    for a, b in zip(parameters(straight), parameters(resumed)):
        assert torch.equal(a, b)
    assert straight.progress == resumed.progress
    np.testing.assert_array_equal(straight.buffer.data["obs"], resumed.buffer.data["obs"])


def test_stop_request_writes_a_checkpoint(tmp_path: Path) -> None:
    trainer = Trainer(SETTINGS, AGENT, tmp_path)
    calls = iter(range(1000))
    assert not trainer.run(300, should_stop=lambda: next(calls) >= 40)
    trainer.close()
    assert read_pointer(tmp_path / LATEST).name == "step-0000000040"
    assert Trainer.resume(tmp_path).progress.env_steps == 40


WRITER = """
import sys
from pathlib import Path
from lanrocli.agent import SACSettings
from lanrocli.train import Trainer, TrainSettings
trainer = Trainer(TrainSettings(task="reach", env={"objects": 2}, learning_starts=10_000, eval_every=10**9),
                  SACSettings(buffer_size=2000), Path(sys.argv[1]))
trainer.run(1)
trainer.checkpoint()
print("ready", flush=True)
while True:
    trainer.run(trainer.progress.env_steps + 1)
    trainer.checkpoint()
"""


@pytest.mark.parametrize("delay", [0.05, 0.23, 0.41])
def test_sigkill_during_checkpoint_writes_leaves_a_loadable_checkpoint(tmp_path: Path, delay: float) -> None:
    process = subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    assert process.stdout is not None and process.stdout.readline().strip() == "ready"
    time.sleep(delay)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    trainer = Trainer.resume(tmp_path)
    assert trainer.progress.env_steps >= 1
    trainer.run(trainer.progress.env_steps + 5)
    trainer.close()


def test_pickled_objects_are_refused(tmp_path: Path) -> None:
    trainer = Trainer(SETTINGS, AGENT, tmp_path)
    trainer.run(5)
    directory = trainer.checkpoint()
    trainer.close()
    state = torch.load(directory / AGENT_FILE, weights_only=True)
    state["note"] = Path("/etc/passwd")  # any object beyond tensors and plain data
    torch.save(state, directory / AGENT_FILE)
    with pytest.raises(CheckpointError, match="other than tensors and plain data"):
        load_agent_state(directory)
    with pytest.raises(CheckpointError):
        Trainer.resume(tmp_path)


def test_missing_checkpoint_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="no checkpoint pointer"):
        Trainer.resume(tmp_path)


def test_cuda_request_without_cuda_is_a_clear_error() -> None:
    from lanrocli.train import pick_device

    assert pick_device("cpu").type == "cpu"
    assert pick_device(None).type == ("cuda" if torch.cuda.is_available() else "cpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="no CUDA device"):
            pick_device("cuda")


def test_two_environments_in_subprocesses_collect_whole_episodes(tmp_path: Path) -> None:
    settings = TrainSettings(task="reach", env={"objects": 2}, seed=1, envs=2, eval_every=10**9, learning_starts=10**6)
    trainer = Trainer(settings, AGENT, tmp_path)
    trainer.run(240)
    trainer.close()
    assert trainer.progress.env_steps == 240 and trainer.progress.episodes >= 4
    buffer = trainer.buffer
    starts = np.unique(buffer.data["episode_start"][: buffer.high][buffer.data["valid"][: buffer.high]])
    for start in starts:
        length = int(buffer.data["episode_length"][start])
        obs, next_obs = buffer.data["obs"][start : start + length], buffer.data["next_obs"][start : start + length]
        # Consecutive transitions chain: no transition spans two episodes.
        np.testing.assert_array_equal(obs[1:], next_obs[:-1])
