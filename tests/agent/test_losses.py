"""The update's losses compiled (``SACSettings.compile``): the gradients and metrics of the eager update, with
each agent's compiled entries its own."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lanrocli.agent.buffer.transitions import Batch
from lanrocli.agent.losses import sac_losses
from lanrocli.agent.sac import SACAgent
from tests.agent.episodes import OBS_DIM
from tests.agent.test_sac import _agent, _batch, _grounding_batch


def _gradients(agent: SACAgent, batch: Batch) -> tuple[dict[str, float], list[torch.Tensor]]:
    """The metrics of one update and the gradients it leaves, the optimiser's step held back."""
    agent.optimizer.step = lambda: None  # type: ignore[method-assign,assignment,return-value]
    metrics = agent.update(batch)
    grads = [
        p.grad if p.grad is not None else torch.zeros_like(p)
        for p in (*agent.actor.parameters(), *agent.critic.parameters())
    ]
    return metrics, [*grads, agent.log_alpha.grad]


@pytest.mark.slow
def test_compiled_losses_give_the_eager_updates_gradients_for_each_agent_in_one_process() -> None:
    """Two agents of different shapes compiled in one process, each checked against its eager twin on a
    batch with grounding labels and on one without (another compiled entry, as is an update that trains the
    critic alone): an agent reusing another's entries would fail on shapes or give other gradients."""
    rng = np.random.default_rng(0)
    observations = rng.normal(size=(50, OBS_DIM))
    labelled = _grounding_batch(rng)
    labelled.label[::3] = -1
    unlabelled = _batch(rng, 128)
    settings_tried = (
        {"architecture": "objects", "critics": 2, "actor_every": 2},  # the second update trains the critic alone
        {"architecture": "flat", "hidden_layers": 2},
    )
    for settings in settings_tried:
        eager, compiled = _agent(seed=1, **settings), _agent(seed=1, compile=True, **settings)  # type: ignore[arg-type]
        for agent in (eager, compiled):
            agent.update_normalizer(observations)
        for batch in (labelled, unlabelled, labelled):
            want_metrics, want = _gradients(eager, batch)
            got_metrics, got = _gradients(compiled, batch)
            for name, value in want_metrics.items():
                assert got_metrics[name] == pytest.approx(value, rel=1e-4, abs=1e-6), name
            for a, b in zip(got, want):
                torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6)
        assert (want_metrics["grounding_loss"] > 0.0) == (settings["architecture"] == "objects")


class FailsBackward(torch.autograd.Function):
    """The identity, whose backward fails as a compiled backward that cannot be built does."""

    @staticmethod
    def forward(ctx: object, x: torch.Tensor) -> torch.Tensor:
        return x.clone()

    @staticmethod
    def backward(ctx: object, grad: torch.Tensor) -> torch.Tensor:
        raise RuntimeError("no C++ compiler works here")


def _fails_forward(*args: object) -> None:
    raise RuntimeError("no C++ compiler works here")


def _fails_backward(*args: object) -> tuple[torch.Tensor, torch.Tensor]:
    loss, metrics = sac_losses(*args)  # type: ignore[arg-type]
    return FailsBackward.apply(loss), metrics


@pytest.mark.parametrize("failing", [_fails_forward, _fails_backward], ids=["forward", "backward"])
def test_an_update_that_cannot_be_compiled_runs_eager_and_says_so(
    failing: object, caplog: pytest.LogCaptureFixture
) -> None:
    """Where torch cannot build its kernels (no working C++ compiler on CPU, say), forward or backward, the
    agent's first update warns and computes what the eager agent computes, with the same noise, rather than
    a run dying at its first update."""
    rng = np.random.default_rng(0)
    batch = _grounding_batch(rng)
    eager, compiled = _agent(seed=1, architecture="objects"), _agent(seed=1, architecture="objects", compile=True)
    compiled._compiled = failing  # type: ignore[assignment]
    with caplog.at_level("WARNING", logger="lanrocli.agent.sac"):
        got_metrics, got = _gradients(compiled, batch)
    want_metrics, want = _gradients(eager, batch)
    assert "torch.compile failed" in caplog.text and "no C++ compiler" in caplog.text
    assert got_metrics == want_metrics
    assert all(torch.equal(a, b) for a, b in zip(got, want))
    assert compiled._compiled is None  # later updates do not try again
    assert torch.equal(compiled.generator.get_state(), eager.generator.get_state())
