"""The sentences' reading in C++ gives the Python's numbers bit for bit, and a machine that cannot build it
trains on with the Python."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch

from lanrocli.agent import encoder, native
from lanrocli.agent.encoder import _distinct
from lanrocli.agent.gru import read_sentences
from lanrocli.language import PAD_ID, sample_sentence

from tests.agent.episodes import OBS_DIM, VOCAB
from tests.agent.test_sac import _agent, _grounding_batch


def _built() -> native.Reader:
    reader = native.native_reader()
    assert reader is not None, "the C++ reading did not build: the tests need a C++ compiler and ninja (see its warning)"
    return reader


def _python(
    tables: torch.Tensor, weight_hh: torch.Tensor, bias_hh: torch.Tensor, tokens: torch.Tensor, trained: int
) -> torch.Tensor:
    """encode's reading where the C++ one cannot be built."""
    sentences, inverse = _distinct(tokens, tables.shape[1])
    return read_sentences(tables, weight_hh, bias_hh, sentences, PAD_ID, trained).index_select(1, inverse)


def _tokens(rng: np.random.Generator, rows: int, width: int, vocab: int) -> torch.Tensor:
    """Rows of words then padding, of every length from none to ``width``, many repeated."""
    tokens = rng.integers(1, vocab, size=(rows, width))
    tokens[np.arange(width) >= rng.integers(0, width + 1, size=(rows, 1))] = PAD_ID
    tokens[rng.random(rows) < 0.4] = tokens[0]
    return torch.as_tensor(tokens)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_cpp_reading_gives_the_pythons_summaries_and_gradients_bit_for_bit(dtype: torch.dtype) -> None:
    """Random GRUs and batches: sentences that order as numbers (vocab ** width < 2 ** 63) and as rows of words,
    sizes whose rows do not fill a vector register (where a kernel's last elements round apart), members
    that are not trained, empty sentences."""
    read = _built()
    rng = np.random.default_rng(0)
    for case in range(40):
        members = int(rng.integers(1, 4))
        trained = int(rng.integers(1, members + 1))
        size, vocab = int(rng.choice([1, 3, 7, 8, 17, 32])), int(rng.choice([5, 61]))
        tokens = _tokens(rng, int(rng.integers(1, 80)), int(rng.choice([3, 10, 16])), vocab)
        generator = torch.Generator().manual_seed(case)
        leaves = [
            torch.randn(shape, dtype=dtype, generator=generator).requires_grad_()
            for shape in ((members, vocab, 3 * size), (members, 3 * size, size), (members, 3 * size))
        ]
        weights = torch.randn(members, tokens.shape[0], size, dtype=dtype, generator=generator)
        results = []
        for reading in (read, lambda *args: _python(*args[:4], args[5])):
            summaries = reading(*leaves, tokens, PAD_ID, trained)
            results.append([summaries.detach(), *torch.autograd.grad((summaries * weights).sum(), leaves)])
        for got, want in zip(*results):
            assert got.shape == want.shape and torch.equal(got, want), case


def test_a_batch_without_words_reads_as_zeros_that_nothing_learns_from() -> None:
    tables, weight_hh, bias_hh = (torch.randn(shape, requires_grad=True) for shape in ((2, 9, 12), (2, 12, 4), (2, 12)))
    tokens = torch.zeros(5, 6, dtype=torch.int64)
    for summaries in (_built()(tables, weight_hh, bias_hh, tokens, PAD_ID, 2), _python(tables, weight_hh, bias_hh, tokens, 2)):
        assert torch.equal(summaries, torch.zeros(2, 5, 4)) and not summaries.requires_grad


def test_updates_with_the_cpp_reading_leave_every_weight_as_the_python_does(monkeypatch: pytest.MonkeyPatch) -> None:
    """The shipped agent's shape (its own actor encoder, a target critic stepping along without gradients)
    through twenty updates: bit for bit, so a run's numbers do not depend on whether the machine built it."""
    _built()
    rng = np.random.default_rng(0)
    batches = [_grounding_batch(rng) for _ in range(20)]
    for batch in batches:  # sentences of many lengths, corrections and negations among them, as a curriculum's
        texts = [sample_sentence(rng, "push", corrections=True, negations=True).text for _ in range(2 * len(batch.obs))]
        batch.instruction, batch.next_instruction = np.split(VOCAB.encode_many(texts), 2)
    observations = rng.normal(size=(50, OBS_DIM))
    states = []
    for built in (True, False):
        if not built:
            monkeypatch.setattr(encoder, "native_reader", lambda: None)
        agent = _agent(seed=3, architecture="objects")
        agent.update_normalizer(observations)
        for batch in batches:
            agent.update(batch)
        states.append(agent.state_dict())
    for network in ("actor", "critic", "target_critic"):
        for (name, a), b in zip(states[0][network].items(), states[1][network].values()):
            assert torch.equal(a, b), f"{network}.{name}"


def test_a_machine_that_cannot_build_it_is_warned_and_reads_in_python(monkeypatch: pytest.MonkeyPatch) -> None:
    from torch.utils import cpp_extension

    def no_ninja(*args: object, **kwargs: object) -> None:
        raise RuntimeError("Ninja is required to load C++ extensions")

    monkeypatch.setattr(cpp_extension, "load", no_ninja)
    expected = "could not build its C\\+\\+ reading of sentences \\(Ninja is required.*apt-get install g\\+\\+ ninja-build"
    with pytest.warns(RuntimeWarning, match=expected):
        assert native.load.__wrapped__(native.READING) is None


def test_a_lock_left_by_a_process_killed_while_loading_does_not_stop_the_next() -> None:
    """torch's build lock is a plain file: a process killed while holding it (a run killed in its first
    update) left it behind, and every later process waited for it for ever."""
    _built()
    folder = native.build_folder()
    (folder / native.TORCH_LOCK).touch()
    code = "from lanrocli.agent.native import native_reader; assert native_reader() is not None"
    subprocess.run([sys.executable, "-c", code], timeout=120, check=True)
    assert not (folder / native.TORCH_LOCK).exists()
