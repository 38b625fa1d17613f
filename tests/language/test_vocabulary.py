"""One grammar-wide vocabulary: every spoken word, nothing else, fixed length, defined failure modes."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lanrocli.language import (
    PAD_ID,
    TASKS,
    UNK_ID,
    SentenceTooLong,
    Vocabulary,
    all_sentences,
    grammar_vocabulary,
    sample_sentence,
)
from lanrocli.language import vocabulary as vocabulary_module
from lanrocli.language.grammar import grammar_words
from lanrocli.language.vocabulary import agent_vocabulary, listed_words, unlearned_words


def test_vocabulary_is_exactly_the_words_the_grammar_speaks() -> None:
    spoken: set[str] = set()
    max_words = 0
    for task in TASKS:
        for s in all_sentences(task, corrections=True, negations=True, rare=True):
            words = s.text.split()
            spoken.update(words)
            max_words = max(max_words, len(words))
    vocab = grammar_vocabulary()
    assert vocab.words[PAD_ID] == "<pad>" and vocab.words[UNK_ID] == "<unk>"
    assert set(vocab.words[2:]) == spoken
    assert vocab.max_length == max_words == 10


def test_order_is_stable() -> None:
    assert grammar_vocabulary().words == Vocabulary.from_dict(grammar_vocabulary().to_dict()).words
    assert list(grammar_vocabulary().words[2:]) == listed_words()


def test_every_word_of_the_grammar_has_its_line_in_the_word_ids_file() -> None:
    missing = sorted(set(grammar_words()) - set(listed_words()))
    assert not missing, f"append {missing} at the end of lanrocli/language/word_ids.txt (never reorder it)"
    assert len(set(listed_words())) == len(listed_words())


def test_a_word_added_to_the_grammar_takes_the_next_id_and_shifts_none(monkeypatch: pytest.MonkeyPatch) -> None:
    before = grammar_vocabulary()
    monkeypatch.setattr(vocabulary_module, "grammar_words", lambda: ["aardvark", *grammar_words(), "zebu"])
    vocabulary_module._grammar_vocabulary.cache_clear()
    try:
        after = grammar_vocabulary()
        assert after.words[: len(before)] == before.words
        assert after.words[len(before) :] == ("aardvark", "zebu")
    finally:
        vocabulary_module._grammar_vocabulary.cache_clear()


def test_an_agent_reads_with_its_own_vocabulary_or_the_one_it_was_trained_with() -> None:
    mine = Vocabulary(["push", "the", "red"], 4)
    assert agent_vocabulary(mine.to_dict(), len(mine)) == mine
    older = agent_vocabulary(None, 12)  # a checkpoint that stored none: the first ten words of the stable order
    assert older.words[2:] == tuple(listed_words()[:10]) and older.max_length == grammar_vocabulary().max_length
    with pytest.raises(ValueError, match="do not belong together"):
        agent_vocabulary(mine.to_dict(), len(mine) + 1)


def test_unknown_words_names_the_grammar_words_an_agent_lacks() -> None:
    assert unlearned_words(grammar_vocabulary()) == []
    assert unlearned_words(Vocabulary(list(grammar_vocabulary().words[3:]), 10)) == [grammar_vocabulary().words[2]]


@pytest.mark.parametrize("task", TASKS)
def test_every_sentence_round_trips(task: str) -> None:
    vocab = grammar_vocabulary()
    for s in itertools.islice(all_sentences(task, corrections=True, negations=True, rare=True), 0, None, 7):
        ids = vocab.encode(s.text)
        assert ids.dtype == np.int64 and ids.shape == (vocab.max_length,)
        assert UNK_ID not in ids
        assert vocab.decode(ids) == s.text


@given(st.integers(0, 2**32 - 1), st.sampled_from(TASKS), st.booleans(), st.booleans(), st.booleans())
def test_sampled_sentences_round_trip(seed: int, task: str, corr: bool, neg: bool, rare: bool) -> None:
    vocab = grammar_vocabulary()
    s = sample_sentence(np.random.default_rng(seed), task, corr, neg, rare)
    assert vocab.decode(vocab.encode(s.text)) == s.text


def test_unknown_words_map_to_unk() -> None:
    vocab = grammar_vocabulary()
    ids = vocab.encode("reach the mauve thingamajig")
    assert list(ids[:4]) == [vocab.token_id("reach"), vocab.token_id("the"), UNK_ID, UNK_ID]
    assert vocab.decode(ids) == "reach the <unk> <unk>"
    assert vocab.token_id("<pad>") == UNK_ID  # a literal '<pad>' in text is not padding


def test_over_long_sentence_is_a_clear_error() -> None:
    vocab = grammar_vocabulary()
    with pytest.raises(SentenceTooLong, match="11 words"):
        vocab.encode(" ".join(["red"] * 11))


def test_empty_sentence_is_all_padding() -> None:
    assert not grammar_vocabulary().encode("").any()


def test_decode_rejects_ids_outside_the_vocabulary() -> None:
    with pytest.raises(ValueError, match="outside"):
        grammar_vocabulary().decode([3, 999])


def test_from_dict_rejects_malformed_data() -> None:
    with pytest.raises(ValueError):
        Vocabulary.from_dict({"words": "red", "max_length": 3})
    with pytest.raises(ValueError, match="reserved"):
        Vocabulary(["<pad>", "red"], 3)
