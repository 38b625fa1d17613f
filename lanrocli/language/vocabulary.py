"""The one vocabulary of the whole curriculum and the fixed-length encoding of sentences into token ids.

Word ids are part of every trained agent (its embedding's rows), so they never shift: their order is the
list in ``word_ids.txt``, and a word the grammar gains without a line there is appended after them. An
agent's own vocabulary is saved with each of its checkpoints and read back by everything that runs it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from functools import cache
from importlib import resources
from typing import Any

import numpy as np

from lanrocli.language.grammar import grammar_words, max_sentence_words
from lanrocli.tasks import TASK_VERBS

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


WORD_IDS_FILE = "word_ids.txt"


def listed_words() -> list[str]:
    """The words of ``word_ids.txt`` in id order."""
    text = resources.files(__package__).joinpath(WORD_IDS_FILE).read_text(encoding="utf-8")
    return [line.strip() for line in text.splitlines() if line.strip() and not line.startswith("#")]


def stable_order(words: Iterable[str], listed: Sequence[str]) -> list[str]:
    """``listed`` in its order, then the ``words`` it lacks in sorted order: ids already given never move."""
    known = set(listed)
    return list(listed) + sorted(set(words) - known)


def grammar_vocabulary(corrections: int = 1) -> Vocabulary:
    """The vocabulary of every word any stage may speak, in stable id order, with L from the grammar for
    sentences of up to ``corrections`` corrections."""
    return _grammar_vocabulary(corrections, tuple(TASK_VERBS.items()))


@cache
def _grammar_vocabulary(corrections: int, verbs: tuple[tuple[str, tuple[str, ...]], ...]) -> Vocabulary:
    """Kept per set of registered tasks: a task registered for a while has its verbs in the vocabulary built
    meanwhile, and the vocabulary of the tasks before it is the one built before, not one with its verbs."""
    return Vocabulary(stable_order(grammar_words(), listed_words()), max_sentence_words(corrections))


def agent_vocabulary(saved: dict[str, Any] | None, vocab_size: int) -> Vocabulary:
    """The vocabulary an agent of ``vocab_size`` embedding rows was trained with: the one saved with it,
    or, for a checkpoint that holds none, the first words of the stable order (its ids were the same)."""
    if saved:
        vocabulary = Vocabulary.from_dict(saved)
    else:
        words = stable_order(grammar_words(), listed_words())[: vocab_size - 2]
        vocabulary = Vocabulary(words, max_sentence_words())
    if len(vocabulary) != vocab_size:
        raise ValueError(
            f"the agent embeds {vocab_size} token ids but its vocabulary has {len(vocabulary)}: "
            "the checkpoint's agent and vocabulary do not belong together"
        )
    return vocabulary


def unlearned_words(vocabulary: Vocabulary) -> list[str]:
    """The grammar's words that ``vocabulary`` lacks: an agent reads each of them as ``<unk>``."""
    return [w for w in grammar_vocabulary().words[2:] if w not in vocabulary]
