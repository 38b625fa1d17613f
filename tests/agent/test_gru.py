"""GRUs stepped together with a hand-written backward pass give nn.GRU's states and gradients."""

from __future__ import annotations

import torch
from torch import nn

from lanrocli.agent.gru import read_sentences

VOCAB, EMBEDDING, SIZE = 30, 8, 6


def _grus(members: int) -> tuple[list[nn.Embedding], list[nn.GRU]]:
    torch.manual_seed(0)
    embeddings = [nn.Embedding(VOCAB, EMBEDDING, padding_idx=0).double() for _ in range(members)]
    grus = [nn.GRU(EMBEDDING, SIZE, batch_first=True).double() for _ in range(members)]
    return embeddings, grus


def _tokens(lengths: list[int], width: int) -> torch.Tensor:
    generator = torch.Generator().manual_seed(1)
    tokens = torch.randint(1, VOCAB, (len(lengths), width), generator=generator)
    for row, length in enumerate(lengths):
        tokens[row, length:] = 0
    return tokens


def _ours(
    embeddings: list[nn.Embedding], grus: list[nn.GRU], tokens: torch.Tensor, trained: int | None = None
) -> torch.Tensor:
    tables = torch.stack([e.weight @ g.weight_ih_l0.t() + g.bias_ih_l0 for e, g in zip(embeddings, grus)])
    weight_hh = torch.stack([g.weight_hh_l0 for g in grus])
    bias_hh = torch.stack([g.bias_hh_l0 for g in grus])
    return read_sentences(tables, weight_hh, bias_hh, tokens, pad_id=0, trained=trained)


def _reference(embeddings: list[nn.Embedding], grus: list[nn.GRU], tokens: torch.Tensor) -> torch.Tensor:
    """nn.GRU over each sentence's words alone, one sentence at a time."""
    states = []
    for embedding, gru in zip(embeddings, grus):
        rows = []
        for row in tokens:
            words = row[row != 0]
            if words.numel() == 0:
                rows.append(torch.zeros(SIZE, dtype=torch.float64))
            else:
                rows.append(gru(embedding(words.unsqueeze(0)))[1][0, 0])
        states.append(torch.stack(rows))
    return torch.stack(states)


def test_states_and_gradients_are_those_of_nn_gru_for_every_member() -> None:
    embeddings, grus = _grus(3)
    tokens = _tokens([5, 1, 0, 7, 3, 7, 2, 0, 4], width=9)  # unsorted, ties, empty rows, padding past the longest
    weights = torch.randn(3, tokens.shape[0], SIZE, dtype=torch.float64)
    parameters = [p for module in (*embeddings, *grus) for p in module.parameters()]

    ours = _ours(embeddings, grus, tokens)
    ours_grads = torch.autograd.grad((ours * weights).sum(), parameters)
    reference = _reference(embeddings, grus, tokens)
    reference_grads = torch.autograd.grad((reference * weights).sum(), parameters)

    torch.testing.assert_close(ours, reference, rtol=1e-12, atol=1e-12)
    for mine, theirs in zip(ours_grads, reference_grads):
        torch.testing.assert_close(mine, theirs, rtol=1e-10, atol=1e-12)


def test_a_member_gets_no_gradient_from_another_members_output() -> None:
    embeddings, grus = _grus(2)
    tokens = _tokens([4, 6, 2], width=6)
    ours = _ours(embeddings, grus, tokens)
    grads = torch.autograd.grad(ours[0].sum(), [*grus[1].parameters(), embeddings[1].weight], allow_unused=True)
    assert all(g is None or torch.count_nonzero(g) == 0 for g in grads)


def test_members_past_the_trained_ones_step_along_without_gradients() -> None:
    embeddings, grus = _grus(3)
    tokens = _tokens([3, 6, 1, 6], width=7)
    weights = torch.randn(3, tokens.shape[0], SIZE, dtype=torch.float64)
    parameters = [[*e.parameters(), *g.parameters()] for e, g in zip(embeddings, grus)]
    all_trained = _ours(embeddings, grus, tokens)
    expected = torch.autograd.grad((all_trained * weights).sum(), parameters[0] + parameters[1])
    two_trained = _ours(embeddings, grus, tokens, trained=2)
    grads = torch.autograd.grad((two_trained * weights).sum(), parameters[0] + parameters[1] + parameters[2])
    torch.testing.assert_close(two_trained, all_trained)
    for mine, theirs in zip(grads, expected):
        torch.testing.assert_close(mine, theirs)
    assert all(torch.count_nonzero(g) == 0 for g in grads[len(expected) :])


def test_a_batch_without_words_reads_zeros() -> None:
    embeddings, grus = _grus(2)
    out = _ours(embeddings, grus, torch.zeros(4, 5, dtype=torch.int64))
    assert out.shape == (2, 4, SIZE) and torch.count_nonzero(out) == 0
