"""Replayed updates leave every weight as updates run from Python do, for every shape of agent; a recording
refuses what it could not replay faithfully; a machine that cannot build the replay trains on without it."""

from __future__ import annotations

import copy
import warnings
from collections.abc import Callable

import numpy as np
import pytest
import torch
from torch.fx.experimental.proxy_tensor import make_fx

from lanrocli.agent import native, replay
from lanrocli.agent.losses import sac_losses
from lanrocli.agent.sac import SACAgent
from lanrocli.agent.buffer.transitions import Batch
from lanrocli.language import PAD_ID, sample_sentence

from tests.agent.episodes import OBS_DIM, VOCAB
from tests.agent.test_sac import _agent, _batch, _grounding_batch

SHAPES = [
    {"architecture": "objects", "sentence_in_trunk": False, "critics": 1},  # the shipped curricula's
    {"architecture": "flat"},
    {"architecture": "objects", "critics": 2, "see_rest": True},
    {"architecture": "objects", "share_encoder": True, "clip_target": False, "max_grad_norm": 1.0},
    {"architecture": "objects", "autotune_alpha": False, "grounding": 0.0, "hidden_layers": 2},
]


def _batches(rng: np.random.Generator, count: int) -> list[Batch]:
    """Labelled and unlabelled batches in turn and one without words (each kind is its own recording), with
    sentences of every length and ends, failures and multi-step transitions among the rows."""
    batches = []
    for k in range(count):
        batch = _grounding_batch(rng, 64) if k % 3 else _batch(rng, 64)
        texts = [sample_sentence(rng, "push", corrections=True, negations=True).text for _ in range(128)]
        batch.instruction, batch.next_instruction = np.split(VOCAB.encode_many(texts), 2)
        if k == 7:  # no word at all: it reads as zeros, which nothing learns from
            batch.instruction[:], batch.next_instruction[:] = PAD_ID, PAD_ID
        batch.done = rng.random(64) < 0.3
        batch.failed = rng.random(64) < 0.1
        batch.steps = rng.integers(1, 4, size=64)
        batches.append(batch)
    return batches


def _trained(settings: dict[str, object], batches: list[Batch], replayed: bool, threads: int = 1) -> SACAgent:
    agent = _agent(seed=5, **settings, replay=replayed)
    agent.update_threads = threads
    agent.update_normalizer(np.random.default_rng(1).normal(size=(50, OBS_DIM)))
    for batch in batches:
        agent.update(batch)
    assert (agent._replay is not None) == replayed, "the replay did not build: the tests need a C++ compiler and ninja"
    return agent


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("settings", SHAPES, ids=lambda settings: ",".join(f"{k}={v}" for k, v in settings.items()))
def test_replayed_updates_leave_every_weight_and_metric_as_python_does(settings: dict[str, object], threads: int) -> None:
    batches = _batches(np.random.default_rng(0), 12)
    replayed, python = _trained(settings, batches, True, threads), _trained(settings, batches, False)
    assert len(replayed._replay._recordings) == 3  # one per kind of batch, reused after
    want, got = python.state_dict(), replayed.state_dict()
    for network in ("actor", "critic", "target_critic"):
        for name, value in want[network].items():
            assert torch.equal(got[network][name], value), f"{network}.{name}"
    assert torch.equal(got["log_alpha"], want["log_alpha"])
    moments = [(a["exp_avg"], b["exp_avg"]) for a, b in zip(got["optimizer"]["state"].values(), want["optimizer"]["state"].values())]
    assert all(torch.equal(a, b) for a, b in moments)
    extra = _batches(np.random.default_rng(9), 1)[0]
    copied = copy.deepcopy(replayed)  # records anew, for its own tensors
    assert replayed.update(extra) == python.update(extra) == copied.update(extra)
    assert all(torch.equal(a, b) for a, b in zip(copied.actor.parameters(), replayed.actor.parameters()))


def test_a_recording_replays_on_new_values_and_refuses_a_tensor_that_is_not_an_input() -> None:
    built = native.load(native.REPLAY)
    weight = torch.randn(3, 3, requires_grad=True)

    def gradient(x: torch.Tensor, w: torch.Tensor) -> list[torch.Tensor]:
        return list(torch.autograd.grad((x @ w).tanh().sum(), w))

    recording = replay.Recording(gradient, [torch.randn(4, 3), weight], built)
    x = torch.randn(4, 3)
    (want,) = gradient(x, weight)
    (got,) = recording([x, weight])
    assert torch.equal(got, want)
    def gathered(x: torch.Tensor, columns: torch.Tensor) -> list[torch.Tensor]:
        ys = [x[:, columns], x * 2]  # an index list holding None; an in-place call returning nothing
        torch._foreach_mul_(ys, 3.0)
        return ys

    columns = torch.tensor([2, 0])
    recording = replay.Recording(gathered, [torch.randn(4, 3), columns], built)
    assert all(torch.equal(a, b) for a, b in zip(recording([x, columns]), gathered(x, columns)))
    with pytest.raises(ValueError, match="read tensors that are not its inputs"):
        replay.Recording(lambda x: [x @ weight.detach()], [x], built)


def _changed(x: torch.Tensor) -> list[torch.Tensor]:
    y = x * 1.0
    row = y[0]  # a view: it sees the change below
    before = row + 1.0
    y.mul_(2.0)
    return [before, row + 1.0, y.sum(0)]


def _changed_in_a_list(x: torch.Tensor) -> list[torch.Tensor]:
    y = x * 1.0
    row = y[1]
    before = row * 3.0
    torch._foreach_mul_([x * 2.0, y], 2.0)  # a list of tensors changed in place
    return [before, row * 3.0]


@pytest.mark.parametrize("changed", [_changed, _changed_in_a_list])
def test_calls_made_by_two_threads_follow_what_they_read_and_every_change_in_place(
    changed: Callable[[torch.Tensor], list[torch.Tensor]],
) -> None:
    built = native.load(native.REPLAY)
    x = torch.randn(5, 3)
    graph = make_fx(changed)(x).graph
    program, calls = replay._program(graph, built)
    after = calls.after()
    (changing,) = [index for index, written in enumerate(calls.written) if written]
    (view,) = [index for index, aliasing in enumerate(calls.aliasing) if aliasing and index != changing]
    readers = [index for index, reads in enumerate(calls.reads) if set(reads) & set(calls.results[view])]
    assert min(readers) < changing < max(readers)
    assert all(index in after[changing] for index in readers if index < changing)  # read before, made before
    assert all(changing in after[index] for index in readers if index > changing)  # read after, made after
    recording = replay.Recording(changed, [x], built, threads=2)
    for _ in range(200):
        y = torch.randn(5, 3)
        assert all(torch.equal(a, b) for a, b in zip(recording([y]), changed(y)))
    calls.costs = [1.0] * len(calls.reads)
    order, after_lists = calls.order()
    with pytest.raises(RuntimeError, match="which the order puts after it"):
        program.schedule(2, order[::-1], after_lists)


def test_two_threads_keep_random_draws_in_order_and_leave_a_change_nothing_else_sees_unordered() -> None:
    built = native.load(native.REPLAY)

    def drawn(x: torch.Tensor) -> list[torch.Tensor]:
        inside = (x > 0).logical_and_(x < 1)  # a fresh result only the change reads: no other call sees it
        return [x + torch.randn(5, 3), x * torch.rand(5, 3), inside.float(), x.sin()]

    x = torch.randn(5, 3)
    _, calls = replay._program(make_fx(drawn)(x).graph, built)
    after = calls.after()
    first, second = [index for index, draws in enumerate(calls.drawn) if draws]
    (changing,) = [index for index, written in enumerate(calls.written) if written]
    assert first in after[second]  # the second draw after the first
    unrelated = [i for i in range(changing + 1, len(after)) if not calls.drawn[i] and not set(calls.reads[i]) & set(calls.results[changing])]
    assert unrelated and all(changing not in after[i] for i in unrelated)
    recording = replay.Recording(drawn, [x], built, threads=2)
    for seed in range(50):
        torch.manual_seed(seed)
        want = drawn(x)
        torch.manual_seed(seed)
        assert all(torch.equal(a, b) for a, b in zip(recording([x]), want))


def test_an_error_in_a_call_made_by_a_helper_thread_is_raised_and_the_program_runs_after() -> None:
    built = native.load(native.REPLAY)
    weight = torch.randn(3, 3, requires_grad=True)

    def gradients(x: torch.Tensor, w: torch.Tensor) -> list[torch.Tensor]:
        a, b = (x @ w).tanh(), (x @ w.t()).sigmoid()
        return list(torch.autograd.grad((a * b).sum(), w))

    x = torch.randn(4, 3)
    recording = replay.Recording(gradients, [x, weight], built, threads=2)
    for _ in range(20):
        with pytest.raises(RuntimeError, match="cannot be multiplied|size"):
            recording([torch.randn(4, 5), weight])
        assert torch.equal(recording([x, weight])[0], gradients(x, weight)[0])


def test_a_machine_that_cannot_build_it_is_warned_and_updates_from_python(monkeypatch: pytest.MonkeyPatch) -> None:
    from torch.utils import cpp_extension

    def no_compiler(*args: object, **kwargs: object) -> None:
        raise RuntimeError("Error building extension: g++: not found")

    monkeypatch.setattr(cpp_extension, "load", no_compiler)
    monkeypatch.setattr(replay, "load", native.load.__wrapped__)  # not the build this process made already
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        agent = _agent(architecture="objects")  # an agent that only acts (lanro eval, play) builds nothing
    with pytest.warns(RuntimeWarning, match="could not build its C\\+\\+ replay of an update's operations \\(.*g\\+\\+: not found"):
        agent.update(_grounding_batch(np.random.default_rng(0), 64))
    assert agent._replay is None


def test_losses_that_branch_on_a_value_fail_to_record_and_say_how_to_update_from_python(monkeypatch: pytest.MonkeyPatch) -> None:
    def branching(*args: object, **kwargs: object) -> tuple[torch.Tensor, torch.Tensor]:
        loss, metrics = sac_losses(*args, **kwargs)  # type: ignore[arg-type]
        return (loss if loss > 0 else -loss), metrics

    monkeypatch.setattr(replay, "sac_losses", branching)
    agent = _agent(architecture="objects")
    with pytest.raises(RuntimeError, match="could not be recorded for its replay .*agent.replay: false"):
        agent.update(_grounding_batch(np.random.default_rng(0), 64))


@pytest.mark.parametrize(("cores", "workers", "threads"), [(2, 2, 1), (3, 2, 1), (4, 2, 2), (2, 0, 2), (1, 0, 1)])
def test_a_training_updates_on_two_threads_only_where_a_core_is_spare(
    monkeypatch: pytest.MonkeyPatch, cores: int, workers: int, threads: int
) -> None:
    monkeypatch.setattr(torch, "get_num_interop_threads", lambda: cores)
    assert replay.update_threads(workers) == threads
