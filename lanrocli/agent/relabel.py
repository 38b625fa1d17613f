"""Sentences for hindsight language relabelling: goal sentences that single out one object of a scene.

When the arm did the task on some object, the episode is a success for a sentence that names that object,
whatever the instructor had asked. The replay buffer turns failed episodes into such successes; this module
writes the sentences. They come from the instructor's grammar and must be unambiguous in the scene, else the
relabelled reward would teach the agent that an ambiguous sentence means one particular object.

Two styles, both resolving to the target object:

- plain: ``<verb> the <phrase>`` where the phrase fits the target and no other object;
- corrected: an instruction that does not by itself pick the target (another object's phrase, an ambiguous
  phrase, or a rare colour word the agent may not know) followed by an excuse or edit that identifies the
  target (``push the cube sorry the red cube``), or a negation that rules out the one other object the
  instruction left open (``push the cube not the blue box``).

The buffer draws a few of each per object when an episode is added, so that relabelling at sample time is
only array indexing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lanrocli.language import (
    BEGINNING_WORDS,
    TASK_VERBS,
    Beginning,
    ObjectProps,
    Phrase,
    Vocabulary,
    correction,
    extend,
    identifying_phrases,
    instruction,
    object_phrases,
)

CORRECTING_BEGINNINGS: tuple[Beginning, ...] = (Beginning.EXCUSE, Beginning.EDIT)
"""Beginnings whose correction replaces the instruction's object by the one it names."""

_DRAWS_PER_SENTENCE = 5
"""Uniform numbers a sentence's choices need at most (verb, kind, beginning, two phrases), drawn at once."""


@dataclass(frozen=True)
class TargetPhrases:
    """What the instructor could say to single out one object of a scene.

    ``identifying``: phrases (common words) that fit the target and nothing else.
    ``misleading``: instruction phrases a correction could follow: another object's, one that fits
    several objects, or one with a rare colour word the listener may not know.
    ``negations``: (instruction phrase, negated phrase) pairs: the instruction fits the target and, for a
    listener who knows only the common words, also the negated object; the negated phrase identifies that
    object, and removing it leaves the target alone, whether or not the listener knows the rare words.
    """

    identifying: tuple[Phrase, ...]
    misleading: tuple[Phrase, ...]
    negations: tuple[tuple[Phrase, Phrase], ...]


def target_phrases(objects: Sequence[ObjectProps], target: int) -> TargetPhrases:
    """The phrases that single out ``objects[target]`` among ``objects``."""
    goal = objects[target]
    others = [o for i, o in enumerate(objects) if i != target]
    identifying = tuple(identifying_phrases(goal, others))
    common_ids = {p.words for p in identifying}
    seen: set[str] = set()
    misleading: list[Phrase] = []
    for obj in objects:
        for phrase in object_phrases(obj, rare=True):
            if phrase.words not in common_ids and phrase.words not in seen:
                seen.add(phrase.words)
                misleading.append(phrase)
    negations: list[tuple[Phrase, Phrase]] = []
    for i, other in enumerate(objects):
        if i == target:
            continue
        rest = [o for j, o in enumerate(objects) if j != i]
        for negated in identifying_phrases(other, rest):
            for phrase in object_phrases(goal, rare=True):
                if not _fits_common(phrase, other):
                    continue  # negating an object the instruction never pointed at corrects nothing
                left = [o for o in objects if phrase.matches(o) and not negated.matches(o)]
                left_common = [o for o in objects if _fits_common(phrase, o) and not negated.matches(o)]
                if left == [goal] and left_common == [goal]:
                    negations.append((phrase, negated))
    return TargetPhrases(identifying, tuple(misleading), tuple(negations))


def _fits_common(phrase: Phrase, obj: ObjectProps) -> bool:
    """Does ``phrase`` fit ``obj`` for a listener who does not know rare words (a rare colour fits any)?"""
    return phrase.shape in (None, obj.shape) and (phrase.rare or phrase.colour in (None, obj.colour))


def _pick(items: Sequence, u: float):  # type: ignore[no-untyped-def]
    """``items[floor(u * len)]`` for ``u`` in [0, 1): one uniform draw, taken from a pre-drawn array."""
    return items[int(u * len(items))]


def plain_sentence(verbs: Sequence[str], phrases: TargetPhrases, u: np.ndarray) -> str:
    """``<verb> the <identifying phrase>``, chosen by the uniform draws ``u[0]`` and ``u[1]``."""
    return instruction(_pick(verbs, u[0]), _pick(phrases.identifying, u[1]))


def corrected_sentence(verbs: Sequence[str], phrases: TargetPhrases, negations: bool, u: np.ndarray) -> str:
    """An instruction that misses the target, then a correction that fixes it, chosen by the draws ``u``.

    There is always a misleading instruction to correct: every colour has a rare word.
    """
    kinds = list(CORRECTING_BEGINNINGS)
    if negations and phrases.negations:
        kinds.append(Beginning.NEGATION)
    verb = _pick(verbs, u[0])
    kind = _pick(kinds, u[1])
    beginning = _pick(BEGINNING_WORDS[kind], u[2])
    if kind is Beginning.NEGATION:
        phrase, negated = _pick(phrases.negations, u[3])
        return extend(instruction(verb, phrase), correction(beginning, negated))
    return extend(
        instruction(verb, _pick(phrases.misleading, u[3])),
        correction(beginning, _pick(phrases.identifying, u[4])),
    )


@dataclass(frozen=True)
class SentencePool:
    """Relabelling sentences for one episode, as token ids.

    ``plain`` and ``corrected``: uint8 [rows, n_objects, L]. ``identifiable``: bool [n_objects]; where it
    is false (an object with an identical twin) no sentence can name the object and its rows are padding.
    """

    plain: np.ndarray
    corrected: np.ndarray
    identifiable: np.ndarray


def sentence_pool(
    task: str,
    objects: Sequence[ObjectProps],
    rows: int,
    vocabulary: Vocabulary,
    negations: bool,
    rng: np.random.Generator,
) -> SentencePool:
    """``rows`` plain and ``rows`` corrected sentences for every identifiable object of the scene."""
    verbs = TASK_VERBS[task]
    n = len(objects)
    plain = np.zeros((rows, n, vocabulary.max_length), dtype=np.uint8)
    corrected = np.zeros_like(plain)
    identifiable = np.zeros(n, dtype=bool)
    for k in range(n):
        phrases = target_phrases(objects, k)
        if not phrases.identifying:
            continue
        identifiable[k] = True
        draws = rng.random((rows, 2, _DRAWS_PER_SENTENCE))
        plain[:, k] = vocabulary.encode_many(plain_sentence(verbs, phrases, u[0]) for u in draws)
        corrected[:, k] = vocabulary.encode_many(corrected_sentence(verbs, phrases, negations, u[1]) for u in draws)
    return SentencePool(plain, corrected, identifiable)
