"""The grammar produces every production of the paper's two BNF figures and nothing else."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lanrocli.core.choices import CorrectionForm
from lanrocli.language import (
    BEGINNING_WORDS,
    COLOURS,
    RARE_WORD_COLOURS,
    SHAPE_WORDS,
    TASK_VERBS,
    TASKS,
    ObjectProps,
    all_corrections,
    all_instructions,
    all_sentences,
    ambiguous_phrases,
    identifying_phrases,
    sample_sentence,
)

SHAPE_WORD_LIST = [w for words in SHAPE_WORDS.values() for w in words]


def bnf_objects(rare: bool) -> set[str]:
    """OBJECT ::= COLOR SHAPE | SHAPE object | COLOR object, written out independently of the package."""
    colours = list(COLOURS) + (list(RARE_WORD_COLOURS) if rare else [])
    return (
        {f"{c} {s}" for c, s in itertools.product(colours, SHAPE_WORD_LIST)}
        | {f"{s} object" for s in SHAPE_WORD_LIST}
        | {f"{c} object" for c in colours}
    )


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("rare", [False, True])
def test_every_instruction_production_is_generated_once(task: str, rare: bool) -> None:
    expected = {f"{v} the {o}" for v in TASK_VERBS[task] for o in bnf_objects(rare)}
    generated = [text for text, _ in all_instructions(task, rare)]
    assert len(generated) == len(set(generated))
    assert set(generated) == expected


@pytest.mark.parametrize("negations", [False, True])
def test_every_correction_production_is_generated_once(negations: bool) -> None:
    beginnings = ["sorry", "excuse me", "no i meant", "pardon", "actually"] + (["not"] if negations else [])
    expected = {f"{b} the {o}" for b in beginnings for o in bnf_objects(rare=False)}
    generated = [text for text, _ in all_corrections(negations)]
    assert len(generated) == len(set(generated))
    assert set(generated) == expected


def test_extended_instructions_are_instruction_then_correction() -> None:
    sentences = list(all_sentences("push", corrections=True, negations=True, rare=True))
    instructions = {t for t, _ in all_instructions("push", rare=True)}
    corrections = {t for t, _ in all_corrections(negations=True)}
    assert (
        len(sentences) == len(instructions) * len(corrections) == 837 * 594
    )  # 3 verbs x (27 colour words x 9 shape words + 9 + 27)
    sample = sentences[:: len(sentences) // 997]
    for s in sample:
        assert s.instruction in instructions and s.correction in corrections
        assert s.text == f"{s.instruction} {s.correction}"


def test_sentences_are_lower_case_single_spaced_without_punctuation() -> None:
    for s in itertools.islice(all_sentences("lift", corrections=True, negations=True, rare=True), 0, None, 101):
        assert s.text == s.text.lower() == " ".join(s.text.split())
        assert all(ch.isalpha() or ch == " " for ch in s.text)


def test_corrections_never_use_rare_words() -> None:
    rare = set(RARE_WORD_COLOURS)
    for text, _ in all_corrections(negations=True):
        assert not rare & set(text.split())


def test_beginnings_cover_excuse_negation_edit() -> None:
    assert BEGINNING_WORDS[CorrectionForm.EXCUSE] == ("sorry", "excuse me", "no i meant", "pardon")
    assert BEGINNING_WORDS[CorrectionForm.NEGATION] == ("not",)
    assert BEGINNING_WORDS[CorrectionForm.EDIT] == ("actually",)


def test_sampling_is_reproducible_and_valid() -> None:
    a = [sample_sentence(np.random.default_rng(3), "grasp", True, True, True) for _ in range(1)]
    b = [sample_sentence(np.random.default_rng(3), "grasp", True, True, True) for _ in range(1)]
    assert a == b
    rng = np.random.default_rng(0)
    instructions = {t for t, _ in all_instructions("grasp", rare=True)}
    corrections = {t for t, _ in all_corrections(negations=True)}
    seen_beginnings = set()
    for _ in range(500):
        s = sample_sentence(rng, "grasp", corrections=True, negations=True, rare=True)
        assert s.instruction in instructions and s.correction in corrections
        seen_beginnings.add(s.beginning)
    assert seen_beginnings == set(CorrectionForm)


objects = st.builds(ObjectProps, st.sampled_from(COLOURS), st.sampled_from(tuple(SHAPE_WORDS)))


@settings(max_examples=300, deadline=None)
@given(st.lists(objects, min_size=2, max_size=3), st.booleans())
def test_uniqueness_helper_never_calls_an_ambiguous_phrase_unique(table: list[ObjectProps], rare: bool) -> None:
    target, others = table[0], table[1:]
    unique = identifying_phrases(target, others, rare)
    ambiguous = ambiguous_phrases(target, others, rare)
    for phrase in unique:
        assert phrase.matches(target)
        assert sum(phrase.matches(o) for o in table) == 1
    for phrase in ambiguous:
        assert phrase.matches(target) and sum(phrase.matches(o) for o in table) >= 2
    # Together they are every true phrase of the target, and no phrase is both.
    assert {p.words for p in unique}.isdisjoint({p.words for p in ambiguous})
    if target not in others:
        # The colour-and-shape phrase always names a distinct object uniquely.
        assert any(p.colour and p.shape for p in unique)


def test_uniqueness_on_a_hand_built_table() -> None:
    green_cube, green_cuboid, red_cube = (
        ObjectProps("green", "cube"),
        ObjectProps("green", "cuboid"),
        ObjectProps("red", "cube"),
    )
    unique = {p.words for p in identifying_phrases(green_cube, [green_cuboid, red_cube])}
    assert unique == {"green cube", "green box", "green block"}
    ambiguous = {p.words for p in ambiguous_phrases(green_cube, [green_cuboid, red_cube])}
    assert ambiguous == {"cube object", "box object", "block object", "green object"}
    assert {p.words for p in identifying_phrases(red_cube, [green_cube, green_cuboid])} >= {"red object", "red cube"}


def test_object_props_reject_unknown_properties() -> None:
    with pytest.raises(ValueError, match="colour 'azure'"):
        ObjectProps("azure", "cube")
    with pytest.raises(ValueError, match="shape 'sphere'"):
        ObjectProps("red", "sphere")
