"""Acting replayed answers as acting from Python does, action for action and attention for attention, for every
shape of agent, while its weights and statistics change and its calls' shapes come and go."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from lanrocli.agent import replay, sac
from lanrocli.agent.acting import explore
from lanrocli.agent.replay import ReplayedActing
from lanrocli.agent.sac import SACAgent
from lanrocli.core.choices import ActingAttention

from tests.agent.episodes import OBS_DIM, VOCAB
from tests.agent.test_replay import SHAPES, _batches
from tests.agent.test_sac import _agent


def _observations(rng: np.random.Generator, rows: int) -> dict[str, np.ndarray]:
    """``rows`` observations with empty object slots among them, and sentences of two lengths, repeated and
    empty among them: a few shapes of call, which recur."""
    texts = ["push the red cube", "not the green one", ""]
    instruction = VOCAB.encode_many([texts[k] for k in rng.integers(0, len(texts), size=rows)])
    observation = rng.normal(size=(rows, OBS_DIM)).astype(np.float32)
    observation[rng.random(rows) < 0.3, -3:] = 0.0
    return {"observation": observation, "instruction": instruction}


@pytest.mark.parametrize("settings", SHAPES, ids=lambda settings: ",".join(f"{k}={v}" for k, v in settings.items()))
def test_replayed_acting_answers_as_acting_from_python_does(settings: dict[str, object]) -> None:
    replayed, python = _agent(seed=5, **settings), _agent(seed=5, **settings, replay=False)
    replayed._acting = acting = ReplayedActing(replayed, after=2)
    assert python._acting is None
    rng, batches = np.random.default_rng(0), iter(_batches(np.random.default_rng(1), 3))
    for step in range(30):
        obs = _observations(rng, 2)
        if step % 10 == 5:  # new weights, statistics and acting rule: the replay reads them as they are now
            for agent in (replayed, python):
                agent.update_normalizer(obs["observation"])
                if settings["architecture"] == "objects":
                    agent.act_by(ActingAttention.ARGMAX if step == 15 else ActingAttention.SOFT)
            batch = next(batches)
            assert replayed.update(batch) == python.update(batch)
        assert np.array_equal(replayed.act(obs), python.act(obs)), step
        (actions, attention), (want, want_attention) = replayed.act_and_attend(obs), python.act_and_attend(obs)
        assert np.array_equal(actions, want), step
        assert (attention is None) == (want_attention is None) and (attention is None or np.array_equal(attention, want_attention))
        unbatched = {name: value[0] for name, value in obs.items()}
        assert np.array_equal(replayed.act(unbatched, deterministic=True), python.act(unbatched, deterministic=True))
    recorded = set(acting._recordings)
    assert recorded and recorded == {key for key, calls in acting._calls.items() if calls >= 2}

    copied: SACAgent = copy.deepcopy(replayed)  # records anew, for its own tensors
    assert copied._acting is not None and not copied._acting._recordings and not copied._acting._calls
    assert set(acting._recordings) == recorded  # the original keeps its own
    copied._acting._after = 1
    obs = _observations(rng, 2)
    assert np.array_equal(copied.act(obs, deterministic=True), python.act(obs, deterministic=True))
    assert copied._acting._recordings


def test_acting_is_recorded_only_once_a_shape_recurs() -> None:
    agent = _agent(seed=1)
    assert agent._acting is not None
    obs = _observations(np.random.default_rng(2), 2)
    for _ in range(agent._acting._after - 1):
        agent.act(obs)
    assert not agent._acting._recordings
    agent.act(obs)
    assert len(agent._acting._recordings) == 1


def test_a_machine_that_cannot_build_the_replay_acts_from_python(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(replay, "load", lambda library: None)  # as native.load answers after its warning
    agent, python = _agent(seed=1), _agent(seed=1, replay=False)
    assert agent._acting is not None
    agent._acting._after = 1
    for obs in (_observations(np.random.default_rng(k), 2) for k in range(3)):
        assert np.array_equal(agent.act(obs), python.act(obs))
    assert not agent._acting._recordings


def test_acting_that_branches_on_a_value_fails_to_record_and_says_how_to_act_from_python(monkeypatch: pytest.MonkeyPatch) -> None:
    def branching(agent: SACAgent, raw: torch.Tensor, *rest: torch.Tensor) -> list[torch.Tensor]:
        actions = explore(agent, raw, *rest)
        return actions if raw.sum() > 0 else [-action for action in actions]

    monkeypatch.setattr(sac, "explore", branching)
    agent = _agent(seed=1)
    assert agent._acting is not None
    agent._acting._after = 1
    with pytest.raises(RuntimeError, match=r"acting \(branching\) could not be recorded .*agent.replay: false"):
        agent.act(_observations(np.random.default_rng(0), 2))
