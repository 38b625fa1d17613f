"""Generalisation splits: training episodes never contain what a holdout keeps out, each split's always do.

Episodes are drawn as the environment draws them (scene, then the instructor's dialogue, with the arm's
first mistake scripted), without physics, so thousands are cheap; relabelled sentences are drawn as the
replay buffer draws them.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lanrocli.agent.buffer.relabel import sentence_pool
from lanrocli.core.choices import Kind, Mode, Split
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.instructor import Instructor, InstructorSettings
from lanrocli.envs.scene import Scene, check_scenes, sample_objects
from lanrocli.language import COLOURS, RARE_WORD_COLOURS, SHAPE_WORDS, ObjectProps, grammar_vocabulary
from lanrocli.language.holdout import Holdout

HOLDOUT = Holdout(
    pairs=("red cylinder", "yellow cuboid"),
    correction_words=("block", "brick", "barrel"),
    late_corrections=(11, 20),
    common_ground=("crimson", "jade", "cobalt", "amber", "lilac", "apricot", "salmon", "teal", "umber"),
)
SETTINGS = InstructorSettings(correction_rate=0.7, negations=True, max_delay=10, rare_words=True)
SHAPE_OF = {word: shape for shape, words in SHAPE_WORDS.items() for word in words}
COLOUR_OF = {c: c for c in COLOURS} | RARE_WORD_COLOURS


def named_pairs(text: str) -> set[tuple[str, str]]:
    """Every colour-shape pair a sentence names by two adjacent words, read independently of the grammar."""
    words = text.split()
    return {(COLOUR_OF[a], SHAPE_OF[b]) for a, b in itertools.pairwise(words) if a in COLOUR_OF and b in SHAPE_OF}


def episode(seed: int, split: Split | None, settings: InstructorSettings = SETTINGS) -> tuple[Instructor, Scene]:
    """One episode's scene and dialogue; the arm does the task on a wrong object from step 3 on."""
    rng = np.random.default_rng(seed)
    instructor = Instructor("push", settings, HOLDOUT, split)
    challenge = instructor.draw_challenge(rng)
    objects, goal = sample_objects(
        rng, Mode.COLOUR_SHAPE, 3, challenge is Kind.AMBIGUITY, challenge is Kind.COMMON_GROUND, HOLDOUT, split
    )
    scene = Scene(objects, goal, np.zeros((3, 2)))
    instructor.start(rng, scene, challenge)
    wrong = int(rng.choice([i for i in range(3) if i != goal]))
    achieved = np.zeros(3, dtype=bool)
    for step in range(1, 40):
        achieved[wrong] = step >= 3
        instructor.observe(rng, step, achieved)
    return instructor, scene


def held_pairs() -> set[tuple[str, str]]:
    return {(o.colour, o.shape) for o in HOLDOUT.pairs}


def test_a_held_out_pair_is_never_in_a_training_episode_and_always_the_goal_of_the_split() -> None:
    named_in_training = 0
    for seed in range(2000):
        instructor, scene = episode(seed, None)
        assert not set(scene.objects) & set(HOLDOUT.pairs)
        assert not named_pairs(instructor.text) & held_pairs()
        named_in_training += bool(named_pairs(instructor.text))
    assert named_in_training > 500  # the reader above does find pairs where sentences name them
    goals = set()
    for seed in range(300):
        instructor, scene = episode(seed, Split.PAIRS)
        assert scene.goal in HOLDOUT.pairs and not set(scene.others(scene.goal_index)) & set(HOLDOUT.pairs)
        goals.add(scene.goal)
    assert goals == set(HOLDOUT.pairs)


def test_held_out_correction_words_are_heard_in_instructions_only_and_in_every_correction_of_the_split() -> None:
    held = set(HOLDOUT.correction_words)
    in_instructions = spoken = 0
    for seed in range(2000):
        instructor, _ = episode(seed, None)
        in_instructions += bool(held & set(instructor.instruction_text.split()))
        if instructor.spoken is not None:
            spoken += 1
            assert not held & set(instructor.spoken.text.split()), instructor.text
    assert in_instructions > 100 and spoken > 1000
    for seed in range(500):
        instructor, _ = episode(seed, Split.CORRECTION_WORDS)
        if instructor.spoken is not None:
            assert held & set(instructor.spoken.text.split()), instructor.text


def test_late_corrections_wait_longer_than_any_in_training() -> None:
    def delays(split: Split | None) -> set[int]:
        found = set()
        for seed in range(400):
            spoken = episode(seed, split)[0].spoken
            if spoken is not None:
                found.add(spoken.spoken_at - spoken.triggered_at)
        return found

    assert delays(None) == set(range(0, 11))
    assert delays(Split.LATE_CORRECTIONS) == set(range(11, 21))


@pytest.mark.parametrize("split", [Split.LATE_CORRECTIONS, Split.CORRECTION_WORDS])
def test_a_splits_control_is_the_same_episode_with_nothing_held_out(split: Split) -> None:
    """The control of a split (the split's seeds, ``split`` None) must differ from it in what the split holds
    out alone: the same scene, goal, instruction and mistake, so the drop between them is that part's."""
    settings = InstructorSettings(correction_rate=1.0, negations=True, max_delay=10, rare_words=True)
    compared = 0
    for seed in range(200):
        (held, held_scene), (control, control_scene) = (episode(seed, s, settings) for s in (split, None))
        assert held.instruction_text == control.instruction_text
        assert held_scene.objects == control_scene.objects and held_scene.goal == control_scene.goal
        if held.spoken is None or control.spoken is None:
            assert held.spoken is control.spoken is None  # no misunderstanding and the mistake unseen
            continue
        compared += 1
        assert held.spoken.triggered_at == control.spoken.triggered_at
        delays = [s.spoken_at - s.triggered_at for s in (held.spoken, control.spoken)]
        words = [set(s.text.split()) & set(HOLDOUT.correction_words) for s in (held.spoken, control.spoken)]
        if split is Split.LATE_CORRECTIONS:
            assert delays[0] >= 11 and delays[1] <= 10
        else:
            assert words[0] and not words[1] and delays[0] == delays[1]
    assert compared > 150


def test_held_out_rare_words_are_never_heard_in_training_and_always_in_the_common_ground_split() -> None:
    held = set(HOLDOUT.common_ground)
    rare_in_training = 0
    for seed in range(2000):
        instructor, _ = episode(seed, None)
        words = set(instructor.text.split())
        assert not held & words
        rare_in_training += bool(set(RARE_WORD_COLOURS) & words)
    assert rare_in_training > 100
    common_ground = dataclass_replace_kinds(SETTINGS, (Kind.COMMON_GROUND,))
    for seed in range(300):
        instructor, _ = episode(seed, Split.COMMON_GROUND, common_ground)
        assert held & set(instructor.instruction_text.split()), instructor.text


def dataclass_replace_kinds(settings: InstructorSettings, kinds: tuple[Kind, ...]) -> InstructorSettings:
    return InstructorSettings(1.0, settings.negations, settings.max_delay, settings.rare_words, kinds)


def test_relabelled_sentences_never_say_what_training_never_hears() -> None:
    vocabulary = grammar_vocabulary()
    held_in_corrections, held_anywhere = set(HOLDOUT.correction_words), set(HOLDOUT.common_ground)
    rng = np.random.default_rng(0)
    corrected_sentences = 0
    for seed in range(150):
        objects, _ = sample_objects(np.random.default_rng(seed), Mode.COLOUR_SHAPE, 3, holdout=HOLDOUT)
        pool = sentence_pool("push", objects, 8, vocabulary, True, rng, HOLDOUT)
        for ids in pool.corrected.reshape(-1, vocabulary.max_length):
            text = vocabulary.decode(ids)
            if not text:
                continue
            corrected_sentences += 1
            _, correction = split_at_correction(text)
            assert not held_anywhere & set(text.split()) and not held_in_corrections & set(correction.split()), text
    assert corrected_sentences > 5000
    unfiltered = sentence_pool("push", objects, 64, vocabulary, True, rng)  # the same scene, nothing held out
    said = " ".join(split_at_correction(vocabulary.decode(ids))[1] for ids in unfiltered.corrected.reshape(-1, 10))
    assert held_in_corrections & set(said.split())


def split_at_correction(text: str) -> tuple[str, str]:
    """An extended instruction's two parts: an instruction is four words (one-word verbs, "the", two
    words of object), the correction all that follows."""
    words = text.split()
    return " ".join(words[:4]), " ".join(words[4:])


@pytest.mark.parametrize("split", list(Split))
def test_the_environment_draws_a_splits_episodes(split: Split) -> None:
    env = LanroEnv(
        "push",
        objects=3,
        mode="colour_shape",
        correction_rate=1.0,
        negations=True,
        rare_words=True,
        kinds=["common_ground"] if split is Split.COMMON_GROUND else None,
        holdout=HOLDOUT,
        split=split,
    )
    try:
        for seed in range(10):
            _, info = env.reset(seed=seed)
            goal = info["objects"][info["goal_index"]]
            assert (goal in HOLDOUT.pairs) == (split is Split.PAIRS)
            if split is Split.COMMON_GROUND:
                assert set(HOLDOUT.common_ground) & set(info["instruction_text"].split())
    finally:
        env.close()


def test_a_split_the_holdout_does_not_define_is_refused() -> None:
    with pytest.raises(ValueError, match="holds nothing"):
        Instructor("push", SETTINGS, Holdout(), Split.PAIRS)
    with pytest.raises(ValueError, match="no goal"):
        check_scenes(Mode.COLOUR, 2, Holdout(pairs=("red cylinder",)), Split.PAIRS)


@pytest.mark.parametrize(
    ("holdout", "message"),
    [
        ({"pairs": ("red",)}, "not a colour-shape pair"),
        ({"pairs": ("red cylinder", "red cylinder")}, "more than once"),
        ({"correction_words": ("block", "box", "brick", "barrel")}, "2 for cube"),
        ({"late_corrections": (5, 3)}, "first <= last"),
        ({"common_ground": ("emerald", "jade")}, "every rare word for green"),
    ],
)
def test_a_holdout_refuses_what_it_cannot_hold_out(holdout: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Holdout(**holdout)


def test_a_holdout_round_trips_as_plain_data() -> None:
    assert Holdout.from_dict(HOLDOUT.to_dict()) == HOLDOUT
    assert Holdout.from_dict(None) == Holdout() and Holdout().splits == ()
    assert ObjectProps("red", "cylinder") in HOLDOUT.pairs
