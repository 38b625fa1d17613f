"""One stage of training end to end, resume equivalence, and checkpoints that survive kills and refuse pickles."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from lanrocli.agent.settings import BufferSettings, SACSettings
from lanrocli.envs.settings import EnvSettings
from lanrocli.train.checkpoint import AGENT_FILE, load_agent_state
from lanrocli.train.errors import CheckpointError
from lanrocli.train.runfolder import LATEST, read_pointer
from lanrocli.train.trainer import Trainer, TrainSettings, pick_device, updates_due

SETTINGS = TrainSettings(
    task="push",
    env=EnvSettings(objects=2, correction_rate=0.5),
    seed=3,
    envs=1,
    eval_episodes=2,
    learning_starts=64,
    buffer=BufferSettings(size=5000),
)
AGENT = SACSettings(batch_size=32)


def parameters(trainer: Trainer) -> list[torch.Tensor]:
    agent = trainer.agent
    return [p.detach().clone() for net in (agent.actor, agent.critic, agent.target_critic) for p in net.parameters()]


@pytest.mark.slow
def test_tiny_training_run_end_to_end() -> None:
    trainer = Trainer(SETTINGS, AGENT)
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
    report = trainer.evaluate(first_seed=0)
    assert report.overall.episodes == 2 and all(r.length <= 100 for r in report.results)


@pytest.mark.parametrize(("rate", "envs"), [(1.0, 2), (2.0, 1), (0.5, 2), (0.5, 1), (0.3, 3), (0.0, 2)])
def test_fractional_update_rates_add_up_over_a_run(rate: float, envs: int) -> None:
    due = [updates_due(steps, envs, rate) for steps in range(0, 3000, envs)]
    assert sum(due) == int(3000 * rate + 1e-9)  # nothing lost to rounding, however it is split
    assert max(due) - min(due) <= 1  # and spread evenly, not bunched
    if rate == int(rate):
        assert set(due) == {int(rate) * envs}  # whole rates keep their every-step behaviour


def test_half_an_update_per_step_makes_half_the_updates() -> None:
    trainer = Trainer(dataclasses.replace(SETTINGS, updates_per_step=0.5), AGENT)
    trainer.run(200)
    trainer.close()
    ready = trainer.progress.updates  # updates start once 64 stored steps are whole episodes
    assert ready > 0 and ready <= (200 - 64) / 2 + 1


def test_random_starts_are_for_training_only() -> None:
    trainer = Trainer(dataclasses.replace(SETTINGS, env=SETTINGS.env.replace(random_start=1.0)), AGENT)
    training, evaluation = trainer.env_factory()(), trainer.env_factory(evaluation=True)()
    hands = [env.reset(seed=seed)[0]["observation"][:3] for seed in range(3) for env in (training, evaluation)]
    assert all(not np.allclose(hand, (0.0, 0.0, 0.10), atol=2e-3) for hand in hands[0::2])
    np.testing.assert_allclose(hands[1::2], [(0.0, 0.0, 0.10)] * 3, atol=2e-3)
    training.close()
    evaluation.close()


def test_evaluations_may_speak_corrections_in_every_episode_while_training_keeps_its_share() -> None:
    settings = dataclasses.replace(SETTINGS, eval_correction_rate=1.0)
    trainer = Trainer(settings, AGENT)
    training, evaluation = trainer.env_factory()(), trainer.env_factory(evaluation=True)()
    challenges = [[env.reset(seed=seed)[1]["challenge"] for seed in range(20)] for env in (training, evaluation)]
    assert None in challenges[0] and any(c is not None for c in challenges[0])
    assert None not in challenges[1]
    assert TrainSettings.from_dict(settings.to_dict()) == settings
    assert (
        TrainSettings.from_dict({k: v for k, v in SETTINGS.to_dict().items() if k != "eval_correction_rate"})
        == SETTINGS
    )
    training.close()
    evaluation.close()


def test_sentences_have_room_for_the_longest_chain_of_corrections_from_the_first_stage() -> None:
    chained = dataclasses.replace(SETTINGS, max_corrections=2)  # a later stage corrects twice
    trainer = Trainer(chained, AGENT)
    env = trainer.env_factory()()
    try:
        assert trainer.vocabulary.max_length == trainer.buffer.vocabulary.max_length == 16
        assert env.observation_space["instruction"].shape == (16,) and env.reset(seed=0)[0]["instruction"].shape == (
            16,
        )
    finally:
        env.close()
        trainer.close()


LEVERS = (
    dataclasses.replace(
        SETTINGS, buffer=BufferSettings(size=5000, relabel_negations=True, fresh_targets=True, ground_real=True)
    ),
    SACSettings(batch_size=32, architecture="objects", sentence_in_trunk=False, acting_attention="argmax"),
)
"""The correction levers the curricula use: they change what is stored and sampled."""


@pytest.mark.slow
@pytest.mark.parametrize(("settings", "agent"), [(SETTINGS, AGENT), LEVERS], ids=["defaults", "levers"])
def test_resume_continues_exactly(tmp_path: Path, settings: TrainSettings, agent: SACSettings) -> None:
    straight = Trainer(settings, agent)
    straight.run(300)
    straight.close()

    first = Trainer(settings, agent)
    first.run(150)  # stops mid-episode: push episodes with corrections last up to 100 steps
    first.save(tmp_path / "split", {"note": "kept"})
    first.close()
    resumed, extra = Trainer.load(tmp_path / "split")
    assert resumed.progress.env_steps == 150 and extra == {"note": "kept"}
    resumed.run(300)
    resumed.close()

    for a, b in zip(parameters(straight), parameters(resumed)):
        assert torch.equal(a, b)
    assert straight.progress == resumed.progress
    np.testing.assert_array_equal(straight.buffer.data["obs"], resumed.buffer.data["obs"])


def test_stop_request_ends_the_run_before_the_next_step() -> None:
    trainer = Trainer(SETTINGS, AGENT)
    calls = iter(range(1000))
    assert not trainer.run(300, should_stop=lambda: next(calls) >= 40)
    trainer.close()
    assert trainer.progress.env_steps == 40


def test_entering_a_stage_changes_the_environments_and_keeps_the_learning() -> None:
    settings = TrainSettings(task="reach", env=EnvSettings(objects=2), envs=1, learning_starts=32, object_slots=3)
    trainer = Trainer(settings, AGENT)
    trainer.run(60)
    updates, stored = trainer.progress.updates, trainer.buffer.size
    buffer = dataclasses.replace(settings.buffer, fresh_targets=True)
    trainer.enter_stage(EnvSettings(objects=3, correction_rate=0.5, negations=True), 1, 4, None, buffer)
    trainer.run(200)
    trainer.close()
    assert trainer.progress.updates > updates and trainer.buffer.size > stored and trainer.buffer.negations
    assert trainer.settings.buffer.fresh_targets  # the stage's sampling, saved with the trainer's settings
    # The stage's limit: correction episodes get 100 steps.
    assert trainer.evaluate(first_seed=0, episodes=1).results[0].length <= 100
    three = trainer.buffer.data["objects"][: trainer.buffer.high, 2, 0] != 255
    assert three.any() and not three.all()  # both stages' episodes, in one buffer of 3 object slots


WRITER = """
import sys
from pathlib import Path
from lanrocli.agent.settings import BufferSettings, SACSettings
from lanrocli.envs.settings import EnvSettings
from lanrocli.train.runfolder import LATEST, prune, write_pointer
from lanrocli.train.trainer import Trainer, TrainSettings
out = Path(sys.argv[1])
buffer = BufferSettings(size=2000)
settings = TrainSettings(task="reach", env=EnvSettings(objects=2), learning_starts=10_000, buffer=buffer)
trainer = Trainer(settings, SACSettings())
while True:
    trainer.run(trainer.progress.env_steps + 1)
    directory = trainer.save(out / f"step-{trainer.progress.env_steps:06d}")
    write_pointer(out / LATEST, directory.name)
    prune(out, keep={directory})
    if trainer.progress.env_steps == 1:
        print("ready", flush=True)
"""


@pytest.mark.slow
@pytest.mark.parametrize("delay", [0.05, 0.23, 0.41])
def test_sigkill_during_checkpoint_writes_leaves_a_loadable_checkpoint(tmp_path: Path, delay: float) -> None:
    process = subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    assert process.stdout is not None and process.stdout.readline().strip() == "ready"
    time.sleep(delay)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    trainer, _ = Trainer.load(read_pointer(tmp_path / LATEST))
    assert trainer.progress.env_steps >= 1
    trainer.run(trainer.progress.env_steps + 5)
    trainer.close()


def test_pickled_objects_are_refused(tmp_path: Path) -> None:
    trainer = Trainer(SETTINGS, AGENT)
    trainer.run(5)
    directory = trainer.save(tmp_path / "checkpoint")
    trainer.close()
    state = torch.load(directory / AGENT_FILE, weights_only=True)
    state["note"] = Path("/etc/passwd")  # any object beyond tensors and plain data
    torch.save(state, directory / AGENT_FILE)
    with pytest.raises(CheckpointError, match="other than tensors and plain data"):
        load_agent_state(directory)
    with pytest.raises(CheckpointError):
        Trainer.load(directory)


def test_missing_or_evaluation_only_checkpoints_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="no checkpoint pointer"):
        read_pointer(tmp_path / LATEST)
    trainer = Trainer(SETTINGS, AGENT)
    trainer.run(5)
    light = trainer.save(tmp_path / "best", resumable=False)
    trainer.close()
    assert load_agent_state(light)["updates"] == 0
    with pytest.raises(CheckpointError, match="cannot be resumed from"):
        Trainer.load(light)


def test_cuda_request_without_cuda_is_a_clear_error() -> None:
    assert pick_device("cpu").type == "cpu"
    assert pick_device(None).type == ("cuda" if torch.cuda.is_available() else "cpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="no CUDA device"):
            pick_device("cuda")


@pytest.mark.parametrize("name", ["tpu", "meta", "", "CUDA", "cuda:-1"])
def test_device_names_lanro_does_not_run_on_are_a_clear_error(name: str) -> None:
    with pytest.raises(ValueError, match="not a device lanro runs on"):
        pick_device(name)


def test_a_cuda_index_beyond_the_machines_devices_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    assert pick_device("cuda:1") == torch.device("cuda", 1) and pick_device("cuda").type == "cuda"
    with pytest.raises(ValueError, match="CUDA devices 0 to 1"):
        pick_device("cuda:7")


def test_two_environments_in_subprocesses_collect_whole_episodes(tmp_path: Path) -> None:
    settings = TrainSettings(task="reach", env=EnvSettings(objects=2), seed=1, envs=2, learning_starts=10**6)
    trainer = Trainer(settings, AGENT)
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
