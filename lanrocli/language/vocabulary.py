"""The one vocabulary of the whole curriculum and the fixed-length encoding of sentences into token ids."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from functools import cache

import numpy as np

from lanrocli.language.grammar import grammar_words, max_sentence_words

PAD = "<pad>"
UNK = "<unk>"
PAD_ID = 0
UNK_ID = 1


class SentenceTooLong(ValueError):
    """A sentence has more words than the fixed length L; raised instead of silently cutting it."""


class Vocabulary:
    """Words to ids and back, padded to one length L.

    Id 0 is padding and id 1 is ``<unk>``: a word outside the vocabulary is encoded as ``<unk>`` (and
    decodes as ``<unk>``) so an unseen word is something the agent reads, never an exception. A sentence
    longer than L raises :class:`SentenceTooLong`, because truncating would silently drop the correction.
    """

    def __init__(self, words: Sequence[str], max_length: int) -> None:
        if max_length < 1:
            raise ValueError(f"max_length must be positive, got {max_length}")
        specials = (PAD, UNK)
        clash = [w for w in words if w in specials]
        if clash:
            raise ValueError(f"vocabulary words may not include the reserved tokens {clash}")
        if len(set(words)) != len(words):
            raise ValueError("vocabulary words must be distinct")
        self.words: tuple[str, ...] = specials + tuple(words)
        self.max_length = max_length
        self._ids = {w: i for i, w in enumerate(self.words)}

    @classmethod
    def from_grammar(cls) -> Vocabulary:
        return grammar_vocabulary()

    def __len__(self) -> int:
        return len(self.words)

    def __contains__(self, word: object) -> bool:
        return word in self._ids and word not in (PAD, UNK)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Vocabulary) and self.words == other.words and self.max_length == other.max_length

    def __hash__(self) -> int:
        return hash((self.words, self.max_length))

    def token_id(self, word: str) -> int:
        return self._ids.get(word, UNK_ID) if word not in (PAD, UNK) else UNK_ID

    def encode(self, text: str) -> np.ndarray:
        """``text`` as int64 ids of length L, padded with 0."""
        words = text.split()
        if len(words) > self.max_length:
            raise SentenceTooLong(
                f"sentence {text!r} has {len(words)} words but the vocabulary encodes at most L={self.max_length}"
            )
        ids = np.zeros(self.max_length, dtype=np.int64)
        ids[: len(words)] = [self.token_id(w) for w in words]
        return ids

    def encode_many(self, texts: Iterable[str]) -> np.ndarray:
        """Several sentences as an int64 array of shape (n, L)."""
        rows = [self.encode(t) for t in texts]
        return np.stack(rows) if rows else np.zeros((0, self.max_length), dtype=np.int64)

    def decode(self, ids: Sequence[int] | np.ndarray) -> str:
        """The sentence of ``ids``; padding is dropped wherever it stands."""
        out = []
        for i in np.asarray(ids, dtype=np.int64).ravel():
            if i == PAD_ID:
                continue
            if not 0 <= i < len(self.words):
                raise ValueError(f"token id {int(i)} is outside this vocabulary of {len(self.words)} ids")
            out.append(self.words[i])
        return " ".join(out)

    def to_dict(self) -> dict[str, object]:
        """Plain data for checkpoints: loading it needs no code from the file."""
        return {"words": list(self.words[2:]), "max_length": self.max_length}

    @classmethod
    def from_dict(cls, data: dict[str, object]) -> Vocabulary:
        words = data["words"]
        max_length = data["max_length"]
        if not isinstance(words, list) or not all(isinstance(w, str) for w in words) or not isinstance(max_length, int):
            raise ValueError("vocabulary data must hold a list of words and an integer max_length")
        return cls(words, max_length)


@cache
def grammar_vocabulary() -> Vocabulary:
    """The vocabulary of every word any stage may speak, in sorted order, with L from the grammar."""
    return Vocabulary(grammar_words(), max_sentence_words())
