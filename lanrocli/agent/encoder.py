"""The sentence encoder: a word embedding and a GRU whose state after the last true word summarises the
sentence, and the batched reading of a batch's distinct sentences by several encoders at once."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from lanrocli.agent.gru import read_sentences
from lanrocli.agent.native import Reader, native_reader
from lanrocli.language import PAD_ID


class LanguageEncoder(nn.Module):
    """Word embedding and a GRU; the GRU's state after the sentence's last true word summarises the sentence.

    A unidirectional GRU's state there depends only on the words up to it, so the padding that follows is
    never read as words and the summary does not depend on the padded length. Padding is assumed to follow
    the words, as :meth:`Vocabulary.encode` puts it.

    Acting reads a few sentences at a time with the ``nn.GRU`` module (:meth:`summarise`; a replayed act
    calls the operations that module calls); an update reads a batch's sentences with :func:`encode`, which
    steps the encoders of several networks together and is tested to give the same summaries and gradients
    (see :mod:`lanrocli.agent.gru`).
    """

    def __init__(self, vocab_size: int, embedding_size: int, hidden_size: int) -> None:
        super().__init__()
        self.embedding = nn.Embedding(vocab_size, embedding_size, padding_idx=PAD_ID)
        self.gru = nn.GRU(embedding_size, hidden_size, batch_first=True)
        self.vocab_size = vocab_size
        self.output_size = hidden_size

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        """``tokens``: int64 [B, L] ids padded with 0. Returns float [B, hidden]."""
        return self.summarise(*self.distinct(tokens))

    def distinct(self, tokens: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """What :meth:`summarise` reads of ``tokens``: the distinct sentences cut to the longest one's words (at
        least one), each one's number of words, and per row the index of its distinct sentence. Their shapes
        depend on the words, so this part is Python's: :meth:`summarise` is a function of tensors alone."""
        sentences, inverse = _distinct(tokens, self.vocab_size)
        lengths = (sentences != PAD_ID).sum(dim=1)
        return sentences[:, : max(int(lengths.max()), 1)], lengths, inverse

    def summarise(self, sentences: torch.Tensor, lengths: torch.Tensor, inverse: torch.Tensor) -> torch.Tensor:
        """The summaries [B, hidden] of the rows :meth:`distinct` read."""
        states, _ = self.gru(self.embedding(sentences))
        summary = states[torch.arange(sentences.shape[0], device=sentences.device), (lengths - 1).clamp(min=0)]
        # An empty sentence has read no word: its summary is the GRU's initial state, zero.
        return (summary * (lengths > 0).unsqueeze(1).to(summary.dtype))[inverse]


def encode(encoders: Sequence[LanguageEncoder], tokens: torch.Tensor) -> torch.Tensor:
    """Each encoder's summaries of the sentences ``tokens`` (int64 [B, L]): float [encoders, B, hidden].

    Each distinct sentence of the batch is read once: a batch repeats sentences, and an update reads a
    transition's sentence and its next one, nearly always the same. Encoders whose parameters need no
    gradient (a target network's) should come last: the backward pass then leaves them out.
    """
    tables, weight_hh, bias_hh = stacked_gates(encoders)
    learning = [any(p.requires_grad for p in encoder.parameters()) for encoder in encoders]
    trained = sum(learning) if learning == sorted(learning, reverse=True) else len(encoders)  # learning ones first
    reader = native_reading(tokens.device)
    if reader is not None:  # the same numbers, one C++ call each way
        return reader(tables, weight_hh, bias_hh, tokens, PAD_ID, trained)
    sentences, inverse = _distinct(tokens, encoders[0].vocab_size)
    return read_sentences(tables, weight_hh, bias_hh, sentences, PAD_ID, trained).index_select(1, inverse)


def native_reading(device: torch.device) -> Reader | None:
    """The C++ reading :func:`encode` reads with on ``device`` (:func:`~lanrocli.agent.native.native_reader`): on
    CPU, where the machine could build it; else None."""
    return native_reader() if device.type == "cpu" else None


def _distinct(tokens: torch.Tensor, vocab_size: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The distinct rows of ``tokens`` and, per row, the index of its distinct row."""
    length = tokens.shape[1]
    if vocab_size**length >= 2**63:
        return _distinct_rows(tokens)
    # A sentence read as a number in base vocab_size: distinct numbers are far cheaper to find than
    # distinct rows. Any row with a given number stands for all of them, as they hold the same words.
    powers = vocab_size ** torch.arange(length, device=tokens.device, dtype=torch.int64)
    numbers, inverse = torch.unique((tokens * powers).sum(dim=1), return_inverse=True)
    rows = torch.arange(tokens.shape[0], device=tokens.device)
    first = torch.empty_like(numbers).scatter_(0, inverse, rows)
    return tokens[first], inverse


def _distinct_rows(tokens: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """What ``torch.unique(tokens, dim=0, return_inverse=True)`` gives, rows in the same order (so an update's
    numbers do not change), with far fewer operator calls: NumPy sorts each row as one byte string, where
    ``torch.unique`` compares rows element by element (docs/performance.md). Big-endian bytes of non-negative
    ids sort as the ids do, so the order is the rows' lexicographic order."""
    rows = np.ascontiguousarray(tokens.cpu().numpy().astype(">i8"))
    keys = rows.view(np.dtype((np.void, rows.itemsize * rows.shape[1]))).ravel()
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return tokens[torch.as_tensor(first, device=tokens.device)], torch.as_tensor(inverse.ravel(), device=tokens.device)


def stacked_gates(encoders: Sequence[LanguageEncoder]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The encoders' GRUs as :func:`~lanrocli.agent.gru.read_sentences` steps them together: each word's input
    gates [encoders, vocab, 3 * size], and the recurrent weights [encoders, 3 * size, size] and biases."""
    grus = [encoder.gru for encoder in encoders]
    words = [encoder.embedding.weight for encoder in encoders]
    tables = torch.stack([torch.addmm(gru.bias_ih_l0, word, gru.weight_ih_l0.t()) for word, gru in zip(words, grus)])
    return tables, torch.stack([gru.weight_hh_l0 for gru in grus]), torch.stack([gru.bias_hh_l0 for gru in grus])
