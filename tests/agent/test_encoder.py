"""The sentence encoder: the GRU's state after each sentence's last word, read once per distinct sentence."""

from __future__ import annotations

import torch

from lanrocli.agent.encoder import LanguageEncoder, distinct_sentences


def _tokens() -> torch.Tensor:
    """Sentences of different lengths, padded with 0, with repeats and an empty one."""
    return torch.tensor(
        [[3, 4, 5, 0, 0, 0], [6, 7, 0, 0, 0, 0], [3, 4, 5, 0, 0, 0], [0, 0, 0, 0, 0, 0], [8, 9, 3, 4, 2, 0]]
    )


def test_the_summary_is_the_gru_state_after_the_last_word_whatever_the_padding() -> None:
    torch.manual_seed(0)
    encoder = LanguageEncoder(vocab_size=10, embedding_size=5, hidden_size=4)
    tokens = _tokens()
    summaries = encoder(tokens)
    for row, sentence in zip(summaries, tokens):
        words = sentence[sentence != 0]
        if len(words) == 0:
            torch.testing.assert_close(row, torch.zeros(4))
            continue
        _, state = encoder.gru(encoder.embedding(words).unsqueeze(0))
        torch.testing.assert_close(row, state[0, 0])
    longer = torch.cat([tokens, torch.zeros(5, 7, dtype=torch.int64)], dim=1)
    torch.testing.assert_close(encoder(longer), summaries)


def test_reading_the_distinct_sentences_once_gives_every_row_its_summary_and_gradient() -> None:
    torch.manual_seed(0)
    encoder = LanguageEncoder(vocab_size=10, embedding_size=5, hidden_size=4)
    tokens = _tokens()
    sentences, inverse = distinct_sentences(tokens)
    assert sentences.shape == (4, 5)  # four distinct sentences, the longest of five words
    weights = torch.randn(5, 4)
    (encoder(tokens) * weights).sum().backward()
    want = [p.grad.clone() for p in encoder.parameters()]
    encoder.zero_grad()
    read_once = encoder(sentences)[inverse]
    (read_once * weights).sum().backward()
    torch.testing.assert_close(read_once, encoder(tokens))
    for got, expected in zip([p.grad for p in encoder.parameters()], want):
        torch.testing.assert_close(got, expected)
