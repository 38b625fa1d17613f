"""The GRU's loops in C++ give the Python loops' numbers bit for bit, and a machine that cannot build them
trains on with the Python ones."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lanrocli.agent import gru, native
from lanrocli.agent.gru import PYTHON_STEPS, backward_steps, forward_steps

from lanrocli.language import sample_sentence

from .episodes import OBS_DIM, VOCAB
from .test_sac import _agent, _grounding_batch


def _built() -> native.Steps:
    steps = native.native_steps()
    assert steps is not None, "the C++ GRU steps did not build: the tests need a C++ compiler and ninja (see the warning)"
    return steps


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_cpp_steps_give_the_python_steps_numbers_bit_for_bit(dtype: torch.dtype) -> None:
    """Random shapes: sizes whose rows do not fill a vector register (where a kernel's scalar tail rounds),
    sentences ending at every step, members that are not trained, and a forward pass that keeps nothing."""
    built = _built()
    rng = np.random.default_rng(0)
    for _ in range(40):
        members = int(rng.integers(1, 4))
        trained = int(rng.integers(0, members + 1))
        size = int(rng.choice([1, 3, 7, 8, 17, 32]))
        active = sorted(rng.integers(1, 30, size=int(rng.integers(1, 12))).tolist(), reverse=True)
        generator = torch.Generator().manual_seed(int(rng.integers(1 << 30)))
        inputs = torch.randn(members, sum(active), 3 * size, dtype=dtype, generator=generator)
        weight_hh = torch.randn(members, 3 * size, size, dtype=dtype, generator=generator) / size**0.5
        bias_hh = torch.randn(members, 3 * size, dtype=dtype, generator=generator)
        keep = trained > 0
        want = forward_steps(inputs, weight_hh, bias_hh, active, trained, keep)
        got = built.forward(inputs, weight_hh, bias_hh, active, trained, keep)
        assert len(got) == len(want)
        for a, b in zip(got, want):
            assert a.shape == b.shape and torch.equal(a, b)
        if keep:
            grad = torch.randn(members, active[0], size, dtype=dtype, generator=generator)
            for a, b in zip(built.backward(grad, weight_hh[:trained], *got[1:], active), backward_steps(grad, weight_hh[:trained], *want[1:], active)):
                assert a.shape == b.shape and torch.equal(a, b)


def test_updates_with_the_cpp_steps_leave_every_weight_as_the_python_steps_do(monkeypatch: pytest.MonkeyPatch) -> None:
    """The shipped agent's shape (its own actor encoder, a target critic stepping along without gradients)
    through twenty updates: bit for bit, so a run's numbers do not depend on whether the machine built them."""
    _built()
    rng = np.random.default_rng(0)
    batches = [_grounding_batch(rng) for _ in range(20)]
    for batch in batches:  # sentences of many lengths, corrections and negations among them, as a curriculum's
        texts = [sample_sentence(rng, "push", corrections=True, negations=True).text for _ in range(2 * len(batch.obs))]
        batch.instruction, batch.next_instruction = np.split(VOCAB.encode_many(texts), 2)
    observations = rng.normal(size=(50, OBS_DIM))
    states = []
    for chosen in (None, PYTHON_STEPS):
        if chosen is not None:
            monkeypatch.setattr(gru, "steps", lambda device: chosen)
        agent = _agent(seed=3, architecture="objects")
        agent.update_normalizer(observations)
        for batch in batches:
            agent.update(batch)
        states.append(agent.state_dict())
    for network in ("actor", "critic", "target_critic"):
        for (name, a), b in zip(states[0][network].items(), states[1][network].values()):
            assert torch.equal(a, b), f"{network}.{name}"


def test_a_machine_that_cannot_build_them_is_warned_once_and_reads_with_the_python_steps(monkeypatch: pytest.MonkeyPatch) -> None:
    from torch.utils import cpp_extension

    def no_ninja(*args: object, **kwargs: object) -> None:
        raise RuntimeError("Ninja is required to load C++ extensions")

    monkeypatch.setattr(cpp_extension, "load", no_ninja)
    with pytest.warns(RuntimeWarning, match="could not build its C\\+\\+ GRU steps \\(Ninja is required.*apt-get install g\\+\\+ ninja-build"):
        assert native.native_steps.__wrapped__() is None
    monkeypatch.setattr(gru, "native_steps", lambda: None)
    assert gru.steps(torch.device("cpu")) is PYTHON_STEPS


def test_tensors_off_the_cpu_read_with_the_python_steps() -> None:
    """The C++ loops index CPU memory; a GPU's tensors keep the Python loops, whose operations run there."""
    assert gru.steps(torch.device("cuda")) is PYTHON_STEPS
    assert gru.steps(torch.device("meta")) is PYTHON_STEPS
