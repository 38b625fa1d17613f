"""A checkpoint as one piece of data: written whole, read back exactly, and older checkpoints still read."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from lanrocli.agent.buffer.replay_buffer import ReplayBuffer
from lanrocli.agent.buffer.transitions import EpisodeData
from lanrocli.agent.sac import SACAgent
from lanrocli.agent.settings import SACSettings
from lanrocli.language import COLOURS, SHAPES, ObjectProps, grammar_vocabulary
from lanrocli.train.checkpoint import (
    AGENT_FILE,
    STATE_FILE,
    Checkpoint,
    load_checkpoint,
    save_checkpoint,
    state_from_json,
    state_to_json,
)
from lanrocli.train.errors import CheckpointError
from lanrocli.train.manifest import MANIFEST_FILE
from lanrocli.train.trainer import TrainSettings

VOCABULARY = grammar_vocabulary()
OBS_DIM, ACTION_DIM = 6, 3
SMALL = SACSettings(hidden_size=16, obs_size=16)
BUFFER_SIZE = 20


def episode(rng: np.random.Generator, steps: int) -> EpisodeData:
    length = VOCABULARY.max_length
    tokens = rng.integers(0, len(VOCABULARY), size=(steps, length))
    return EpisodeData(
        observations=rng.standard_normal((steps, OBS_DIM)).astype(np.float32),
        next_observations=rng.standard_normal((steps, OBS_DIM)).astype(np.float32),
        instructions=tokens,
        next_instructions=tokens,
        actions=rng.uniform(-1, 1, (steps, ACTION_DIM)).astype(np.float32),
        rewards=np.full(steps, -1.0, dtype=np.float32),
        terminated=np.zeros(steps, dtype=bool),
        achieved=rng.random((steps, 2)) < 0.3,
        goal_index=0,
        objects=(ObjectProps(COLOURS[0], SHAPES[0]), ObjectProps(COLOURS[1], SHAPES[1])),
        task="push",
    )


def contents(resumable: bool = True) -> Checkpoint:
    rng = np.random.default_rng(3)
    buffer = ReplayBuffer(BUFFER_SIZE, OBS_DIM, ACTION_DIM, max_objects=2, vocabulary=VOCABULARY, seed=1)
    for _ in range(4):
        buffer.add_episode(episode(rng, 7))  # 28 steps in a ring of 20: it wraps
    rng.random(5)  # a generator state away from the seed's
    agent = SACAgent(OBS_DIM, ACTION_DIM, len(VOCABULARY), SMALL, seed=2)
    parts = {}
    if resumable:
        parts = {
            "buffer": buffer,
            "partials": [{"actions": np.ones((2, ACTION_DIM), np.float32)}, {"actions": np.zeros((0, ACTION_DIM))}],
            "environments": [{"start_state": state_to_json(rng.bit_generator.state), "actions": [[0.5, 0.0, -0.5]]}],
        }
    return Checkpoint(
        agent=agent.state_dict(),
        train_settings=TrainSettings(task="push").to_dict(),
        vocabulary=VOCABULARY.to_dict(),
        progress={"env_steps": 28},
        rng=rng.bit_generator.state,
        wall_time=12.5,
        extra={"run": {"stage": 1}},
        **parts,
    )


def test_a_checkpoint_reads_back_exactly(tmp_path: Path) -> None:
    saved = contents()
    directory = save_checkpoint(tmp_path / "step-1", saved)
    assert [p.name for p in tmp_path.iterdir()] == ["step-1"]  # no temporary left behind
    loaded = load_checkpoint(directory)
    for name in ("train_settings", "vocabulary", "progress", "rng", "wall_time", "extra", "environments"):
        assert getattr(loaded, name) == getattr(saved, name), name
    assert loaded.agent_settings == SMALL
    for a, b in zip(saved.agent["actor"].values(), loaded.agent["actor"].values()):
        assert torch.equal(a, b)
    assert saved.buffer is not None and loaded.buffer is not None
    assert loaded.buffer.state()[0] == saved.buffer.state()[0]
    for name, array in saved.buffer.data.items():
        assert array.dtype == loaded.buffer.data[name].dtype and np.array_equal(array, loaded.buffer.data[name]), name
    assert saved.partials is not None and loaded.partials is not None
    assert len(loaded.partials) == 2 and loaded.partials[1]["actions"].shape == (0, ACTION_DIM)
    np.testing.assert_array_equal(loaded.partials[0]["actions"], saved.partials[0]["actions"])


def test_the_agent_settings_are_saved_once(tmp_path: Path) -> None:
    directory = save_checkpoint(tmp_path / "step-1", contents())
    state = json.loads((directory / STATE_FILE).read_text())
    assert "agent_settings" not in state
    assert torch.load(directory / AGENT_FILE, weights_only=True)["settings"] == SMALL.to_dict()


def test_an_evaluation_checkpoint_holds_the_agent_and_state_only(tmp_path: Path) -> None:
    light = save_checkpoint(tmp_path / "best-1", contents(resumable=False))
    assert {p.name for p in light.iterdir()} == {AGENT_FILE, STATE_FILE, MANIFEST_FILE}
    assert load_checkpoint(light, resumable=False).buffer is None
    with pytest.raises(CheckpointError, match="cannot be resumed from"):
        load_checkpoint(light)
    # A resumable checkpoint read for evaluation leaves its buffer unread.
    full = load_checkpoint(save_checkpoint(tmp_path / "step-1", contents()), resumable=False)
    assert (full.buffer, full.partials, full.environments) == (None, None, None)


def test_half_a_resumable_checkpoint_is_refused() -> None:
    whole = contents()
    with pytest.raises(ValueError, match="together or none"):
        Checkpoint(**{**whole.__dict__, "partials": None})


def test_checkpoints_are_never_overwritten(tmp_path: Path) -> None:
    directory = save_checkpoint(tmp_path / "step-1", contents())
    with pytest.raises(CheckpointError, match="never overwritten"):
        save_checkpoint(directory, contents())


def test_random_states_survive_json() -> None:
    state = np.random.default_rng(11).bit_generator.state
    assert state_from_json(json.loads(json.dumps(state_to_json(state)))) == state


def test_a_checkpoint_without_its_manifest_is_refused(tmp_path: Path) -> None:
    directory = save_checkpoint(tmp_path / "step-1", contents())
    (directory / MANIFEST_FILE).unlink()
    with pytest.raises(CheckpointError, match="manifest.json is missing"):
        load_checkpoint(directory)
