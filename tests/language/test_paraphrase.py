"""The paraphrase split's corrections, read back by an independent listener: each must single out the goal
the instructor means, whatever its phrasing."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from lanrocli.core.choices import CorrectionForm, Kind, Mode, Split
from lanrocli.envs.instructor import Instructor, InstructorSettings
from lanrocli.envs.scene import Scene, sample_objects
from lanrocli.language import COLOURS, RARE_WORD_COLOURS, SHAPE_WORDS, ObjectProps, grammar_vocabulary
from lanrocli.language.holdout import Holdout
from lanrocli.language.paraphrase import PARAPHRASES, SYNONYM_SHAPE_WORDS
from lanrocli.tasks import TASK_VERBS, task_class

HELD_OUT_WORDS = ("block", "brick", "barrel")
HOLDOUT = Holdout(correction_words=HELD_OUT_WORDS, paraphrase=True)
SHAPE_OF = {
    word: shape for table in (SHAPE_WORDS, SYNONYM_SHAPE_WORDS) for shape, words in table.items() for word in words
}
EPISODES = 1000


def named(words: list[str]) -> tuple[str | None, str | None]:
    """(colour, shape) a phrase of one or two words names: colour words, shape words (synonyms too), 'object'."""
    colours = [w if w in COLOURS else RARE_WORD_COLOURS[w] for w in words if w in COLOURS or w in RARE_WORD_COLOURS]
    colour = colours[0] if colours else None
    shape = next((SHAPE_OF[w] for w in words if w in SHAPE_OF), None)
    return colour, shape


def fits(phrase: tuple[str | None, str | None], obj: ObjectProps) -> bool:
    return (phrase[0] is None or phrase[0] == obj.colour) and (phrase[1] is None or phrase[1] == obj.shape)


def considered(kind: Kind, instruction: str, objects: tuple[ObjectProps, ...]) -> set[int]:
    """Who a listener who knows the common words still considers after the instruction."""
    phrase = named(instruction.split()[2:])
    if kind is Kind.INSTRUCTION_CORRECTION:
        return set(range(len(objects)))
    if kind is Kind.COMMON_GROUND:  # the rare colour word is not understood
        return {i for i, o in enumerate(objects) if fits((None, phrase[1]), o)}
    return {i for i, o in enumerate(objects) if fits(phrase, o)}


def resolve(correction: str, candidates: set[int], touched: int, objects: tuple[ObjectProps, ...]) -> set[int]:
    """The objects left after hearing ``correction``: a phrase after 'the' narrows to what it fits, one after
    'not the' rules out what it fits, 'the other' rules out the object acted on (and keeps its shape)."""
    words = correction.split()
    left = set(candidates)
    for i, word in enumerate(words):
        if word != "the":
            continue
        phrase = [w for w in words[i + 1 : i + 3] if w in SHAPE_OF or w in COLOURS or w in ("object", "other", "one")]
        if phrase[:1] == ["other"]:
            left -= {touched}
            shape = SHAPE_OF.get(phrase[1]) if len(phrase) > 1 else None
            left = {k for k in left if shape is None or objects[k].shape == shape}
        elif i > 0 and words[i - 1] == "not":
            left -= {k for k in left if fits(named(phrase), objects[k])}
        else:
            left = {k for k in left if fits(named(phrase), objects[k])}
    return left


def episode(seed: int) -> tuple[Instructor, Scene, int]:
    """One paraphrase-split episode without physics: the arm acts on a wrong object at step 3."""
    rng = np.random.default_rng(seed)
    settings = InstructorSettings(correction_rate=1.0, negations=True, negation_rate=0.5, rare_words=True)
    instructor = Instructor("push", settings, HOLDOUT, Split.PARAPHRASE, grammar_vocabulary(2).max_length)
    kind = instructor.draw_challenge(rng)
    objects, goal = sample_objects(
        rng,
        Mode.COLOUR_SHAPE,
        3,
        need_shared=kind is Kind.AMBIGUITY,
        need_same_shape=kind is Kind.COMMON_GROUND,
        holdout=HOLDOUT,
    )
    scene = Scene(objects, goal, np.zeros((3, 2)))
    instructor.start(rng, scene, kind)
    wrong = int(rng.choice([i for i in range(3) if i != goal]))
    achieved = np.zeros(3, dtype=bool)
    achieved[wrong] = True
    for step in range(3, 30):
        if instructor.observe(rng, step, achieved):
            break
    return instructor, scene, wrong


def test_every_paraphrase_singles_out_the_goal_the_instructor_means() -> None:
    phrasings: Counter[str] = Counter()
    vocabulary = grammar_vocabulary(2)
    for seed in range(EPISODES):
        instructor, scene, wrong = episode(seed)
        spoken = instructor.spoken
        assert spoken is not None
        kind = instructor.challenge
        assert kind is not None
        phrasings[spoken.phrasing or "grammar"] += 1
        left = resolve(spoken.text, considered(kind, instructor.instruction_text, scene.objects), wrong, scene.objects)
        assert left == {scene.goal_index}, (instructor.text, scene.objects, scene.goal_index, wrong)
        assert not set(spoken.text.split()) & set(HELD_OUT_WORDS), spoken.text
        vocabulary.encode(instructor.text)  # within the observation's length
    assert set(phrasings) >= {p.name for p in PARAPHRASES}, phrasings
    assert phrasings["grammar"] < EPISODES // 20, phrasings


def test_paraphrase_instructions_use_verbs_training_never_hears() -> None:
    verbs = Counter(episode(seed)[0].instruction_text.split()[0] for seed in range(300))
    held_out = set(task_class("push").paraphrase_verbs)
    assert held_out and not held_out & set(TASK_VERBS["push"])
    assert 0.3 < sum(verbs[v] for v in held_out) / 300 < 0.7


@pytest.mark.parametrize("split", [None, Split.CORRECTION_WORDS])
def test_other_episodes_never_hear_a_paraphrase(split: Split | None) -> None:
    settings = InstructorSettings(correction_rate=1.0, negations=True)
    instructor = Instructor("push", settings, HOLDOUT, split)
    rng = np.random.default_rng(0)
    objects, goal = sample_objects(rng, Mode.COLOUR_SHAPE, 3, holdout=HOLDOUT)
    instructor.start(rng, Scene(objects, goal, np.zeros((3, 2))), Kind.WRONG_OBJECT)
    achieved = np.eye(3, dtype=bool)[(goal + 1) % 3]
    while not instructor.observe(rng, 5, achieved):
        pass
    assert instructor.spoken is not None and instructor.spoken.phrasing is None
    assert instructor.spoken.form in tuple(CorrectionForm)
