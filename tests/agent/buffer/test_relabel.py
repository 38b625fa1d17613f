"""Relabelling sentences: from the grammar, each one the instructor could have spoken for its target after
the arm acted on its touched object, and designating exactly the target."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lanrocli.agent.buffer.relabel import sentence_pool
from lanrocli.core.choices import CorrectionForm
from lanrocli.language import COLOURS, SHAPES, TASKS, ObjectProps, all_sentences, grammar_vocabulary
from tests.agent.sentences import parse, referents

VOCAB = grammar_vocabulary()
GRAMMAR = {s.text for task in TASKS for s in all_sentences(task, corrections=True, negations=True, rare=True)}

objects_strategy = st.builds(ObjectProps, st.sampled_from(COLOURS), st.sampled_from(SHAPES))
scenes = st.lists(objects_strategy, min_size=1, max_size=3)


@settings(max_examples=150, deadline=None)
@given(scene=scenes, task=st.sampled_from(TASKS), negations=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_every_pool_sentence_designates_its_object_alone(
    scene: list[ObjectProps], task: str, negations: bool, seed: int
) -> None:
    pool = sentence_pool(task, scene, 6, VOCAB, negations, np.random.default_rng(seed))
    for k, obj in enumerate(scene):
        has_twin = scene.count(obj) > 1
        assert pool.identifiable[k] == (not has_twin)
        if has_twin:
            assert not pool.plain[:, k].any() and not pool.corrected[:, k].any()
            continue
        assert not pool.corrected[:, k, k].any()
        for row in pool.plain[:, k]:
            parsed = parse(VOCAB.decode(row), task)
            assert parsed.beginning is None and not parsed.noun.rare
            assert referents(parsed, scene) == [k]
        for j in range(len(scene)):
            if j != k:
                for row in pool.corrected[:, k, j]:
                    check_corrected(VOCAB.decode(row), task, scene, k, j, negations)


def check_corrected(text: str, task: str, scene: list[ObjectProps], target: int, touched: int, negations: bool) -> None:
    """What the instructor could say to a listener whose goal is ``target`` after the arm acted on
    ``touched``: a sentence of the grammar whose correction designates the target for a listener who knows
    the rare words and for one who does not, and whose negation, if any, names the touched object."""
    assert text in GRAMMAR, text
    parsed = parse(text, task)
    assert parsed.beginning is not None and parsed.corrected is not None
    assert negations or parsed.beginning is not CorrectionForm.NEGATION
    assert referents(parsed, scene) == [target], text
    assert referents(parsed, scene, knows_rare=False) == [target], text
    if parsed.beginning is CorrectionForm.NEGATION:
        assert parsed.corrected.fits(scene[touched]), text


def test_a_thousand_corrected_sentences_are_the_instructors() -> None:
    rng = np.random.default_rng(7)
    catalogue = [ObjectProps(c, s) for c in COLOURS for s in SHAPES]
    checked = 0
    while checked < 1000:
        n = int(rng.integers(2, 4))
        scene = [catalogue[i] for i in rng.choice(len(catalogue), size=n, replace=False)]
        task = TASKS[int(rng.integers(len(TASKS)))]
        pool = sentence_pool(task, scene, 4, VOCAB, True, rng)
        for k in range(n):
            for j in range(n):
                if j != k:
                    for row in pool.corrected[:, k, j]:
                        check_corrected(VOCAB.decode(row), task, scene, k, j, True)
                        checked += 1


def test_every_form_and_both_kinds_of_negation_are_relabelled() -> None:
    # The instruction may name the touched object ("... the red cube not the red cube") or the target
    # ("... the blue cube not the red cube"): both are negations the instructor speaks.
    scene = (ObjectProps("red", "cube"), ObjectProps("blue", "cube"))
    pool = sentence_pool("push", scene, 200, VOCAB, True, np.random.default_rng(0))
    texts = [VOCAB.decode(row) for row in pool.corrected[:, 1, 0]]
    forms = {parse(text, "push").beginning for text in texts}
    assert forms == set(CorrectionForm)
    negations = [t for t in texts if " not the " in t]
    assert any(t.endswith("red cube not the red cube") for t in negations)
    assert any("blue" in t.split(" not ")[0] and t.endswith("not the red cube") for t in negations)


def test_without_negations_no_negation_is_relabelled() -> None:
    scene = (ObjectProps("red", "cube"), ObjectProps("blue", "cube"), ObjectProps("red", "cylinder"))
    pool = sentence_pool("reach", scene, 64, VOCAB, False, np.random.default_rng(1))
    texts = [VOCAB.decode(row) for row in pool.corrected.reshape(-1, VOCAB.max_length) if row.any()]
    assert texts and not any(" not the " in t for t in texts)


def test_pools_depend_only_on_the_seed() -> None:
    scene = (ObjectProps("red", "cube"), ObjectProps("blue", "cuboid"))
    a = sentence_pool("lift", scene, 8, VOCAB, True, np.random.default_rng(3))
    b = sentence_pool("lift", scene, 8, VOCAB, True, np.random.default_rng(3))
    assert np.array_equal(a.plain, b.plain) and np.array_equal(a.corrected, b.corrected)
