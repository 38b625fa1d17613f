"""The sentence encoder: a word embedding and a GRU whose state after the last true word summarises the
sentence."""

from __future__ import annotations

import torch
from torch import nn

from lanrocli.language import PAD_ID


class LanguageEncoder(nn.Module):
    """Word embedding and a GRU; the GRU's state after the sentence's last true word summarises the sentence.

    A unidirectional GRU's state there depends only on the words up to it, so the padding that follows is
    never read as words and the summary does not depend on the padded length. Padding is assumed to follow
    the words, as :meth:`Vocabulary.encode` puts it.
    """

    def __init__(self, vocab_size: int, embedding_size: int, hidden_size: int) -> None:
        super().__init__()
        self.embedding = nn.Embedding(vocab_size, embedding_size, padding_idx=PAD_ID)
        self.gru = nn.GRU(embedding_size, hidden_size, batch_first=True)
        self.output_size = hidden_size

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        """``tokens``: int64 [B, L] ids padded with 0. Returns float [B, hidden]; an empty sentence, having
        read no word, is summarised by the GRU's initial state, zero."""
        lengths = (tokens != PAD_ID).sum(dim=1)
        states, _ = self.gru(self.embedding(tokens))
        last = states[torch.arange(tokens.shape[0], device=tokens.device), (lengths - 1).clamp(min=0)]
        return last * (lengths > 0).unsqueeze(1).to(last.dtype)


def distinct_sentences(tokens: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The distinct rows of ``tokens`` cut to the longest one's words, and per row the index of its
    distinct row. A batch repeats sentences (a transition's sentence and its next one nearly always
    coincide), so reading each once, and only as far as the longest reaches, saves most of the GRU's steps."""
    sentences, inverse = torch.unique(tokens, dim=0, return_inverse=True)
    longest = max(int((sentences != PAD_ID).sum(dim=1).max()), 1)
    return sentences[:, :longest], inverse
