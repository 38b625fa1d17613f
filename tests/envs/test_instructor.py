"""The instructor's dialogue logic, checked without physics: achieved flags are scripted."""

from __future__ import annotations

import numpy as np
import pytest

from lanrocli.core.choices import Kind, Mode
from lanrocli.envs.instructor import Instructor, InstructorSettings
from lanrocli.envs.scene import Scene, sample_objects
from lanrocli.language import (
    BEGINNING_WORDS,
    RARE_WORD_COLOURS,
    TASK_VERBS,
    ObjectProps,
    all_corrections,
    all_instructions,
    grammar_vocabulary,
)

INSTRUCTIONS = {t for task in TASK_VERBS for t, _ in all_instructions(task, rare=True)}
CORRECTIONS = {t for t, _ in all_corrections(negations=True)}
COLOUR_OF_WORD = dict(RARE_WORD_COLOURS)


def parse_object(words: list[str]) -> tuple[str | None, str | None]:
    """(colour, shape) named by an OBJECT phrase's two words; an independent reading of the grammar."""
    from lanrocli.language import COLOURS, SHAPE_WORDS

    shape_of = {w: s for s, ws in SHAPE_WORDS.items() for w in ws}
    first, second = words
    colour = first if first in COLOURS else COLOUR_OF_WORD.get(first)
    shape = shape_of.get(second) or shape_of.get(first)
    return colour, shape


def fits(named: tuple[str | None, str | None], obj: ObjectProps) -> bool:
    return (named[0] is None or named[0] == obj.colour) and (named[1] is None or named[1] == obj.shape)


def run_episode(seed: int, kind: Kind, negations: bool, delay: int, n_objects: int = 3, mode: Mode = Mode.COLOUR_SHAPE):
    rng = np.random.default_rng(seed)
    settings = InstructorSettings(
        correction_rate=1.0, negations=negations, max_delay=delay, rare_words=True, kinds=(kind,)
    )
    instructor = Instructor("push", settings)
    objects, goal = sample_objects(
        rng, mode, n_objects, need_shared=kind is Kind.AMBIGUITY, need_same_shape=kind is Kind.COMMON_GROUND
    )
    scene = Scene(objects, goal, np.zeros((n_objects, 2)))
    challenge = instructor.draw_challenge(rng)
    assert challenge is kind
    instructor.start(rng, scene, challenge)
    first_text = instructor.text
    wrong = int(rng.choice([i for i in range(n_objects) if i != goal]))
    achieved = np.zeros(n_objects, dtype=bool)
    changed_at = None
    for step in range(1, 60):
        if step >= 5:
            achieved[wrong] = True
        if instructor.observe(rng, step, achieved):
            assert changed_at is None, "a second correction was spoken"
            changed_at = step
    return instructor, scene, wrong, first_text, changed_at


@pytest.mark.parametrize("kind", list(Kind))
@pytest.mark.parametrize("negations", [False, True])
@pytest.mark.parametrize("n_objects", [2, 3])
def test_corrections_are_grammatical_and_name_the_right_object(kind: Kind, negations: bool, n_objects: int) -> None:
    saw_negation = False
    for seed in range(150):
        instructor, scene, wrong, first_text, changed_at = run_episode(seed, kind, negations, 0, n_objects)
        spoken = instructor.spoken
        assert spoken is not None and spoken.kind is kind and changed_at == 5 == spoken.spoken_at
        assert first_text in INSTRUCTIONS and spoken.text in CORRECTIONS
        assert instructor.text == f"{first_text} {spoken.text}"
        words = spoken.text.split()
        named = parse_object(words[-2:])
        if spoken.negation:
            saw_negation = True
            assert words[0] == "not" and fits(named, scene.objects[wrong])
        else:
            assert fits(named, scene.goal)
        # The instruction plus the correction leave exactly the goal for a listener with common words.
        instr_named = parse_object(first_text.split()[-2:])
        rare_used = first_text.split()[-2] in COLOUR_OF_WORD
        if kind is Kind.INSTRUCTION_CORRECTION:
            candidates = set(range(len(scene.objects)))
        else:
            known = (None if rare_used else instr_named[0], instr_named[1])
            candidates = {i for i, o in enumerate(scene.objects) if fits(known, o)}
        if spoken.negation:
            remaining = {i for i in candidates if not fits(named, scene.objects[i])}
        else:
            remaining = {i for i in candidates if fits(named, scene.objects[i])}
        assert remaining == {scene.goal_index}
    if negations and n_objects == 2:
        assert saw_negation


def test_instruction_matches_the_episode_kind() -> None:
    for seed in range(200):
        for kind in Kind:
            instructor, scene, _, first_text, _ = run_episode(seed, kind, False, 0)
            named = parse_object(first_text.split()[-2:])
            matching = {i for i, o in enumerate(scene.objects) if fits(named, o)}
            if kind is Kind.AMBIGUITY:
                assert scene.goal_index in matching and len(matching) >= 2
            elif kind is Kind.INSTRUCTION_CORRECTION:
                assert len(matching) == 1 and scene.goal_index not in matching
            else:
                assert matching == {scene.goal_index}
            assert (first_text.split()[-2] in COLOUR_OF_WORD) == (kind is Kind.COMMON_GROUND)


def without_rare_colour(text: str, objects: tuple[ObjectProps, ...]) -> set[int]:
    """The objects a listener who skips the instruction's rare colour word would still consider."""
    rare, noun = text.split()[-2:]
    assert rare in COLOUR_OF_WORD, f"{text!r} has no rare colour word"
    _, shape = parse_object([rare, noun])
    return {i for i, o in enumerate(objects) if fits((None, shape), o)}


@pytest.mark.parametrize("mode", list(Mode))
@pytest.mark.parametrize("n_objects", [2, 3])
def test_common_ground_instructions_need_their_rare_colour_word(mode: Mode, n_objects: int) -> None:
    settings = InstructorSettings(correction_rate=1.0, rare_words=True, kinds=(Kind.COMMON_GROUND,))
    for seed in range(1000):
        rng = np.random.default_rng(seed)
        instructor = Instructor("lift", settings)
        challenge = instructor.draw_challenge(rng)
        objects, goal = sample_objects(rng, mode, n_objects, need_same_shape=challenge is Kind.COMMON_GROUND)
        instructor.start(rng, Scene(objects, goal, np.zeros((n_objects, 2))), challenge)
        candidates = without_rare_colour(instructor.text, objects)
        assert goal in candidates and len(candidates) >= 2, (instructor.text, objects)


def test_common_ground_speaks_only_rare_phrases_whose_colour_word_is_needed() -> None:
    settings = InstructorSettings(correction_rate=1.0, rare_words=True, kinds=(Kind.COMMON_GROUND,))
    # Only the goal is a cuboid, so "the azure brick" is understood without its colour word; "the azure
    # object" is not, and it identifies the goal, the only blue object.
    scene = Scene((ObjectProps("blue", "cuboid"), ObjectProps("red", "cube")), 0, np.zeros((2, 2)))
    for seed in range(20):
        instructor = Instructor("reach", settings)
        instructor.start(np.random.default_rng(seed), scene, Kind.COMMON_GROUND)
        rare, noun = instructor.text.split()[-2:]
        assert RARE_WORD_COLOURS[rare] == "blue" and noun == "object"
    # The other object is blue too, so "the azure object" would not identify the goal, and "the azure
    # brick" is understood from "brick" alone: no rare phrase is both, and none is spoken.
    scene = Scene((ObjectProps("blue", "cuboid"), ObjectProps("blue", "cube")), 0, np.zeros((2, 2)))
    with pytest.raises(RuntimeError, match="common_ground"):
        Instructor("reach", settings).start(np.random.default_rng(0), scene, Kind.COMMON_GROUND)


@pytest.mark.parametrize("delay", [1, 7, 20])
def test_delayed_corrections_arrive_within_max_delay(delay: int) -> None:
    delays = set()
    for seed in range(200):
        instructor, *_, changed_at = run_episode(seed, Kind.WRONG_OBJECT, True, delay)
        assert instructor.spoken is not None
        waited = instructor.spoken.spoken_at - instructor.spoken.triggered_at
        assert changed_at == instructor.spoken.spoken_at and 0 <= waited <= delay
        delays.add(waited)
    assert len(delays) > 1


def test_plain_episodes_never_correct() -> None:
    rng = np.random.default_rng(0)
    instructor = Instructor("reach", InstructorSettings())
    objects, goal = sample_objects(rng, Mode.COLOUR, 3)
    instructor.start(rng, Scene(objects, goal, np.zeros((3, 2))), instructor.draw_challenge(rng))
    assert instructor.challenge is None
    assert not instructor.observe(rng, 1, np.ones(3, dtype=bool))
    assert instructor.spoken is None


def test_correction_rate_sets_the_share_of_correction_episodes() -> None:
    rng = np.random.default_rng(0)
    instructor = Instructor("reach", InstructorSettings(correction_rate=0.5))
    share = np.mean([instructor.draw_challenge(rng) is not None for _ in range(4000)])
    assert 0.47 < share < 0.53


def test_sentences_fit_the_vocabulary() -> None:
    vocab = grammar_vocabulary()
    for seed in range(50):
        instructor, *_ = run_episode(seed, Kind.COMMON_GROUND, True, 0)
        assert vocab.decode(vocab.encode(instructor.text)) == instructor.text


@pytest.mark.parametrize(
    "kwargs, setting",
    [
        ({"correction_rate": 1.5}, "correction_rate"),
        ({"max_delay": -1}, "max_delay"),
        ({"kinds": ("telepathy",)}, "kinds"),
        ({"kinds": ()}, "kinds"),
        ({"correction_rate": 0.5, "kinds": ("common_ground",)}, "rare_words"),
    ],
)
def test_bad_settings_name_the_setting(kwargs: dict, setting: str) -> None:
    with pytest.raises(ValueError, match=setting):
        InstructorSettings(**kwargs)


def test_beginnings_are_used() -> None:
    starts = set()
    for seed in range(300):
        instructor, *_ = run_episode(seed, Kind.AMBIGUITY, True, 0, n_objects=2)
        assert instructor.spoken is not None
        text = instructor.spoken.text
        starts.add(next(b for words in BEGINNING_WORDS.values() for b in words if text.startswith(b + " ")))
    assert starts == {b for words in BEGINNING_WORDS.values() for b in words}


def spoken_forms(rate: float | None, n_objects: int, mode: Mode, episodes: int = 1000) -> tuple[float, int]:
    """Share of negations among the corrections of ``episodes`` correction episodes of every kind, each
    negation checked to leave the goal alone for a listener who knows only the common words."""
    settings = InstructorSettings(correction_rate=1.0, negations=True, rare_words=True, negation_rate=rate)
    negations = 0
    for seed in range(episodes):
        rng = np.random.default_rng(seed)
        instructor = Instructor("push", settings)
        challenge = instructor.draw_challenge(rng)
        objects, goal = sample_objects(
            rng,
            mode,
            n_objects,
            need_shared=challenge is Kind.AMBIGUITY,
            need_same_shape=challenge is Kind.COMMON_GROUND,
        )
        scene = Scene(objects, goal, np.zeros((n_objects, 2)))
        instructor.start(rng, scene, challenge)
        wrong = int(rng.choice([i for i in range(n_objects) if i != goal]))
        achieved = np.zeros(n_objects, dtype=bool)
        achieved[wrong] = True
        assert instructor.observe(rng, 1, achieved)
        spoken = instructor.spoken
        assert spoken is not None and spoken.negation == (spoken.form == "negation")
        if spoken.negation:
            negations += 1
            named = parse_object(spoken.text.split()[-2:])
            opening = instructor.instruction_text.split()[-2:]
            if challenge is Kind.INSTRUCTION_CORRECTION:
                considered = set(range(n_objects))
            else:
                colour, shape = parse_object(opening)
                known = (None if opening[0] in COLOUR_OF_WORD else colour, shape)
                considered = {i for i, o in enumerate(objects) if fits(known, o)}
            assert fits(named, objects[wrong])
            assert {i for i in considered if not fits(named, objects[i])} == {goal}
    return negations / episodes, negations


@pytest.mark.parametrize("rate", [0.25, 0.5, 1.0])
def test_negation_rate_sets_the_share_of_negations_where_they_are_possible(rate: float) -> None:
    # Between two objects a negation always singles out the goal: the share is the rate.
    share, _ = spoken_forms(rate, 2, Mode.COLOUR)
    assert abs(share - rate) < 0.05
    # Among three, "not the ..." leaves one object only in some scenes; the rate holds among those.
    possible, _ = spoken_forms(1.0, 3, Mode.COLOUR_SHAPE)
    share, negations = spoken_forms(rate, 3, Mode.COLOUR_SHAPE)
    assert 0.4 < possible < 0.8 and abs(share - rate * possible) < 0.05 and negations > 100


def test_negation_rate_needs_negations() -> None:
    with pytest.raises(ValueError, match="negation_rate"):
        InstructorSettings(correction_rate=1.0, negation_rate=0.5)
    with pytest.raises(ValueError, match="negation_rate"):
        InstructorSettings(correction_rate=1.0, negations=True, negation_rate=1.5)


def chain_episode(seed: int, max_corrections: int) -> tuple[Instructor, Scene, list[int]]:
    """An episode whose arm does the task on each wrong object in turn, from step 3, 20 steps apart."""
    rng = np.random.default_rng(seed)
    settings = InstructorSettings(correction_rate=1.0, negations=True, max_delay=5, max_corrections=max_corrections)
    instructor = Instructor("push", settings)
    challenge = instructor.draw_challenge(rng)
    objects, goal = sample_objects(rng, Mode.COLOUR_SHAPE, 3, challenge is Kind.AMBIGUITY)
    scene = Scene(objects, goal, np.zeros((3, 2)))
    instructor.start(rng, scene, challenge)
    wrong = [i for i in rng.permutation(3).tolist() if i != goal]
    achieved = np.zeros(3, dtype=bool)
    for step in range(1, 60):
        for k, index in enumerate(wrong):
            achieved[index] = step >= 3 + 20 * k
        instructor.observe(rng, step, achieved)
    return instructor, scene, wrong


def test_a_chain_of_corrections_singles_out_the_goal_among_what_is_left_each_time() -> None:
    from lanrocli.envs.instructor import MAX_CORRECTIONS
    from lanrocli.language import max_sentence_words
    from lanrocli.language.dialogue import candidates

    lengths = {1: 0, 2: 0}
    for seed in range(300):
        instructor, scene, wrong = chain_episode(seed, MAX_CORRECTIONS)
        assert len(instructor.text.split()) <= max_sentence_words(MAX_CORRECTIONS)
        assert [c.index for c in instructor.corrections] == list(range(1, len(instructor.corrections) + 1))
        assert instructor.text == " ".join([instructor.instruction_text, *(c.text for c in instructor.corrections)])
        left = candidates(instructor.challenge, instructor._phrase, scene.objects)
        for correction, touched in zip(instructor.corrections, wrong):
            words = correction.text.split()
            named = parse_object(words[-2:])
            fitting = {i for i, o in enumerate(scene.objects) if fits(named, o)}
            left -= set(wrong[: correction.index - 1])
            if correction.negation:
                assert touched in fitting and left - fitting == {scene.goal_index}, instructor.text
            else:
                assert left & fitting == {scene.goal_index}, instructor.text
        lengths[len(instructor.corrections)] += 1
    assert lengths[2] > 100  # the checks above ran on chains
    single, _, _ = chain_episode(0, 1)
    assert len(single.corrections) == 1


def test_max_corrections_is_checked() -> None:
    with pytest.raises(ValueError, match="max_corrections must be a whole number within"):
        InstructorSettings(max_corrections=3)
    with pytest.raises(ValueError, match="max_corrections"):
        InstructorSettings(max_corrections=0)


def test_an_answer_singles_out_the_object_the_speaker_means_in_every_kind_of_episode() -> None:
    """1,000 sampled episodes of every kind, each asked at once: the answer is "actually the ...", and an
    independent reading of its words against the scene finds exactly one object: the goal, except in an
    instruction correction, where the speaker believes they meant the object they named."""
    settings = InstructorSettings(correction_rate=0.8, rare_words=True, max_corrections=2, questions=1)
    kinds: set[Kind | None] = set()
    for seed in range(1000):
        rng = np.random.default_rng(seed)
        instructor = Instructor("push", settings)
        challenge = instructor.draw_challenge(rng)
        objects, goal = sample_objects(
            rng,
            Mode.COLOUR_SHAPE,
            3,
            need_shared=challenge is Kind.AMBIGUITY,
            need_same_shape=challenge is Kind.COMMON_GROUND,
        )
        scene = Scene(objects, goal, np.zeros((3, 2)))
        instructor.start(rng, scene, challenge)
        instruction = instructor.text
        answer = instructor.answer(0)
        words = answer.text.split()
        assert words[:2] == ["actually", "the"] and f"{instruction} {answer.text}" == instructor.text
        named = parse_object(words[-2:])
        fitting = {i for i, o in enumerate(objects) if fits(named, o)}
        said = {i for i, o in enumerate(objects) if fits(parse_object(instruction.split()[-2:]), o)}
        meant = next(iter(said)) if challenge is Kind.INSTRUCTION_CORRECTION else goal
        assert fitting == {meant} == {answer.referent}, (seed, challenge, instruction, answer.text)
        assert (meant != goal) == (challenge is Kind.INSTRUCTION_CORRECTION)
        assert not instructor.can_answer
        kinds.add(challenge)
    assert kinds == {None, *Kind}


def test_a_correction_still_follows_an_answer_and_both_take_the_sentence_room() -> None:
    """An instruction correction asked about: the answer names the wrong object again, the arm acts on it,
    and the correction after the mistake names the goal; then no more is spoken in a two-place stage."""
    settings = InstructorSettings(
        correction_rate=1.0, kinds=(Kind.INSTRUCTION_CORRECTION,), max_corrections=2, questions=1
    )
    rng = np.random.default_rng(3)
    instructor = Instructor("push", settings)
    objects, goal = sample_objects(rng, Mode.COLOUR_SHAPE, 3)
    instructor.start(rng, Scene(objects, goal, np.zeros((3, 2))), instructor.draw_challenge(rng))
    answer = instructor.answer(0)
    achieved = np.zeros(3, dtype=bool)
    achieved[answer.referent] = True
    assert instructor.observe(rng, 4, achieved)
    spoken = instructor.spoken
    assert spoken is not None and instructor.text.endswith(f"{answer.text} {spoken.text}")
    achieved[:] = [i != goal for i in range(3)]
    assert not any(instructor.observe(rng, step, achieved) for step in range(5, 40))


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"questions": -1}, "at least 0"),
        ({"questions": 1, "correction_rate": 0.5}, "one must stay free for a correction"),
        ({"questions": 2, "max_corrections": 1}, "raise max_corrections to 2"),
    ],
)
def test_questions_without_room_in_the_sentence_are_refused(changes: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        InstructorSettings(**changes)
