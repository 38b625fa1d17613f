"""Relabelling sentences: from the grammar, and designating exactly the object they are for."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lanrocli.agent.relabel import sentence_pool, target_phrases
from lanrocli.language import COLOURS, SHAPES, TASKS, Beginning, ObjectProps, grammar_vocabulary

from .sentences import parse, referents

VOCAB = grammar_vocabulary()

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
        for row in pool.plain[:, k]:
            parsed = parse(VOCAB.decode(row), task)
            assert parsed.beginning is None and not parsed.noun.rare
            assert referents(parsed, scene) == [k]
        for row in pool.corrected[:, k]:
            parsed = parse(VOCAB.decode(row), task)
            assert parsed.beginning is not None
            assert negations or parsed.beginning is not Beginning.NEGATION
            # Whoever knows the rare words and whoever does not, the sentence means object k.
            assert referents(parsed, scene) == [k]
            assert referents(parsed, scene, knows_rare=False) == [k]
            # A correction corrects something: the instruction alone names another object, fits several,
            # or uses a rare word.
            assert parsed.noun.rare or [i for i, o in enumerate(scene) if parsed.noun.fits(o)] != [k]


def test_negations_appear_where_the_scene_allows_them() -> None:
    scene = (ObjectProps("red", "cube"), ObjectProps("blue", "cube"), ObjectProps("green", "cylinder"))
    assert target_phrases(scene, 0).negations
    pool = sentence_pool("push", scene, 64, VOCAB, True, np.random.default_rng(0))
    kinds = {parse(VOCAB.decode(row), "push").beginning for row in pool.corrected[:, 0]}
    assert kinds == {Beginning.EXCUSE, Beginning.EDIT, Beginning.NEGATION}
    # The cylinder shares nothing with the others: "not the ..." can never leave it alone.
    assert not target_phrases(scene, 2).negations


def test_pools_depend_only_on_the_seed() -> None:
    scene = (ObjectProps("red", "cube"), ObjectProps("blue", "cuboid"))
    a = sentence_pool("lift", scene, 8, VOCAB, True, np.random.default_rng(3))
    b = sentence_pool("lift", scene, 8, VOCAB, True, np.random.default_rng(3))
    assert np.array_equal(a.plain, b.plain) and np.array_equal(a.corrected, b.corrected)
