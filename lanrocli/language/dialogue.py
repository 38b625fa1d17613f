"""What the instructor may say in a scene: the opening instruction of each kind of misunderstanding and the
corrections that resolve it, as functions of the objects alone.

The instructor speaks by these rules, and hindsight relabelling writes its corrected sentences by the same
ones, so every relabelled correction is one the instructor could have spoken in that scene. The rule for a
correction is the paper's: after the instruction, a listener who knows only the common words still weighs
some *candidates*; an excuse or an edit names the goal by a phrase that fits no other candidate, and a
negation names the object the arm acted on by a phrase that rules out every candidate but the goal.
"""

from __future__ import annotations

from collections.abc import Sequence

from lanrocli.core.choices import Kind
from lanrocli.language.grammar import Phrase, ambiguous_phrases, identifying_phrases, object_phrases
from lanrocli.language.properties import ObjectProps


def matching(phrase: Phrase, objects: Sequence[ObjectProps]) -> set[int]:
    """The objects ``phrase`` truthfully describes."""
    return {i for i, o in enumerate(objects) if phrase.matches(o)}


def needs_colour(phrase: Phrase, others: Sequence[ObjectProps]) -> bool:
    """Whether a listener who skips the phrase's colour word could still pick one of ``others``.

    A common-ground instruction tests the rare colour word only if the rest of it leaves a choice: "the
    azure brick" beside no other brick is understood from "brick" alone. The scene of such an episode is
    drawn with another object of the goal's shape (:func:`~lanrocli.envs.scene.sample_objects`), so some
    rare phrase always passes this test.
    """
    return any(phrase.shape is None or o.shape == phrase.shape for o in others)


def _others(objects: Sequence[ObjectProps], index: int) -> list[ObjectProps]:
    return [o for i, o in enumerate(objects) if i != index]


def opening_phrases(
    kind: Kind | None, objects: Sequence[ObjectProps], goal: int, named: int | None = None
) -> list[Phrase]:
    """The phrases an instruction of episode ``kind`` (``None``: a plain episode) may name the goal by.

    ambiguity: a phrase that fits the goal and another object; common ground: one with a rare colour word
    that fits the goal alone and is needed (:func:`needs_colour`); instruction correction: one that
    identifies the object ``named`` (not the goal) instead; wrong object and plain episodes: one that
    identifies the goal.
    """
    target, others = objects[goal], _others(objects, goal)
    if kind is Kind.AMBIGUITY:
        return ambiguous_phrases(target, others)
    if kind is Kind.COMMON_GROUND:
        return [p for p in identifying_phrases(target, others, rare=True) if p.rare and needs_colour(p, others)]
    if kind is Kind.INSTRUCTION_CORRECTION:
        if named is None or named == goal:
            raise ValueError("an instruction correction names another object than the goal: pass `named`")
        return identifying_phrases(objects[named], _others(objects, named))
    return identifying_phrases(target, others)


def candidates(kind: Kind, phrase: Phrase, objects: Sequence[ObjectProps]) -> set[int]:
    """The objects a listener who knows only the common words still considers after an instruction by
    ``phrase`` in an episode of ``kind``."""
    everything = set(range(len(objects)))
    if kind is Kind.INSTRUCTION_CORRECTION:
        return everything  # the correction retracts the instruction's object
    if kind is Kind.COMMON_GROUND:
        if phrase.shape is None:
            return everything
        return {i for i, o in enumerate(objects) if o.shape == phrase.shape}
    return matching(phrase, objects)


def negation_phrases(objects: Sequence[ObjectProps], goal: int, touched: int, considered: set[int]) -> list[Phrase]:
    """Phrases for "not the ..." after the arm acted on ``touched``: they fit it and leave the goal as the
    only one of the ``considered`` candidates. Empty where no phrase does that."""
    return [p for p in object_phrases(objects[touched]) if considered - matching(p, objects) == {goal}]


def naming_phrases(objects: Sequence[ObjectProps], goal: int, considered: set[int]) -> list[Phrase]:
    """Phrases an excuse or an edit names the goal by: of the ``considered`` candidates they fit the goal
    alone (the goal's full description always does)."""
    return [p for p in object_phrases(objects[goal]) if considered & matching(p, objects) == {goal}]
