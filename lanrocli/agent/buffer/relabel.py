"""Sentences for hindsight language relabelling: goal sentences that single out one object of a scene.

When the arm did the task on some object, the episode is a success for a sentence that names that object,
whatever the instructor had asked. The replay buffer turns failed episodes into such successes; this module
writes the sentences. They must be unambiguous in the scene, else the relabelled reward would teach the
agent that an ambiguous sentence means one particular object. Two styles:

- plain: ``<verb> the <phrase>`` where the phrase fits the target and no other object;
- corrected: what the instructor would have said had the target been its goal and had the arm first acted
  on another object (the *touched* one): the opening instruction of one of the episode kinds the scene
  allows, then an excuse, an edit or a negation of the touched object, chosen by the instructor's own rule
  (:mod:`lanrocli.language.dialogue`). So every form the instructor speaks is relabelled, the negation of
  an object the instruction named ("push the red cube not the red cube": an instruction correction) and of
  one it never named ("push the blue cube not the red cube": the arm's own mistake) included.

The buffer draws a few of each per object (and, for corrections, per touched object) when an episode is
added, so that relabelling at sample time is only array indexing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lanrocli.core.choices import CorrectionForm, Kind
from lanrocli.language import (
    BEGINNING_WORDS,
    NAMING_FORMS,
    TASK_VERBS,
    ObjectProps,
    Phrase,
    Vocabulary,
    correction,
    correction_forms,
    extend,
    identifying_phrases,
    instruction,
)
from lanrocli.language.dialogue import candidates, naming_phrases, negation_phrases, opening_phrases
from lanrocli.language.holdout import NOTHING_HELD_OUT, Holdout

_DRAWS_PER_OPENING = 4
"""Uniform numbers an opening instruction's choices need (verb, kind, named object, phrase)."""
_DRAWS = _DRAWS_PER_OPENING + 3
"""Uniform numbers a sentence's choices need, drawn at once: the opening's, then the correction's (form,
beginning words, phrase)."""


def _pick(items: Sequence, u: float):  # type: ignore[no-untyped-def]
    """``items[floor(u * len)]`` for ``u`` in [0, 1): one uniform draw, taken from a pre-drawn array."""
    return items[int(u * len(items))]


@dataclass
class _Scene:
    """One scene's phrase lists, each computed once however many sentences are drawn from it."""

    objects: Sequence[ObjectProps]
    holdout: Holdout = NOTHING_HELD_OUT
    """What training never hears: no relabelled sentence says it either."""

    def __post_init__(self) -> None:
        self._cache: dict[tuple, list[Phrase]] = {}

    def identifying(self, target: int) -> list[Phrase]:
        return self._get(
            ("identifying", target),
            lambda: identifying_phrases(self.objects[target], [o for i, o in enumerate(self.objects) if i != target]),
        )

    def openings(self, kind: Kind, target: int, named: int | None) -> list[Phrase]:
        return self._get(
            ("opening", kind, target, named),
            lambda: self.holdout.instruction_phrases(opening_phrases(kind, self.objects, target, named), None),
        )

    def negations(self, kind: Kind, phrase: Phrase, target: int, touched: int) -> list[Phrase]:
        return self._get(
            ("not", kind, phrase, target, touched),
            lambda: self.holdout.correction_phrases(
                negation_phrases(self.objects, target, touched, candidates(kind, phrase, self.objects)), None
            ),
        )

    def naming(self, kind: Kind, phrase: Phrase, target: int) -> list[Phrase]:
        return self._get(
            ("name", kind, phrase, target),
            lambda: self.holdout.correction_phrases(
                naming_phrases(self.objects, target, candidates(kind, phrase, self.objects)), None
            ),
        )

    def _get(self, key: tuple, compute) -> list[Phrase]:  # type: ignore[no-untyped-def]
        if key not in self._cache:
            self._cache[key] = compute()
        return self._cache[key]


def plain_sentence(verbs: Sequence[str], scene: _Scene, target: int, u: np.ndarray) -> str:
    """``<verb> the <identifying phrase>``, chosen by the uniform draws ``u[0]`` and ``u[1]``."""
    return instruction(_pick(verbs, u[0]), _pick(scene.identifying(target), u[1]))


def corrected_sentence(
    verbs: Sequence[str], scene: _Scene, target: int, touched: int, negations: bool, u: np.ndarray
) -> str:
    """An opening instruction and the correction the instructor would speak after the arm acted on
    ``touched``, chosen by the draws ``u`` (``_DRAWS`` of them): the kind uniformly among those the scene
    allows, then the correction as the instructor chooses it (a negation where one singles out the target,
    else an excuse or an edit)."""
    others = [i for i in range(len(scene.objects)) if i != target and scene.identifying(i)]
    kinds = [k for k in (Kind.AMBIGUITY, Kind.COMMON_GROUND) if scene.openings(k, target, None)]
    kinds += [Kind.INSTRUCTION_CORRECTION] if others else []
    kinds.append(Kind.WRONG_OBJECT)  # the target is identifiable, so this kind is always there
    kind = _pick(kinds, u[1])
    named = _pick(others, u[2]) if kind is Kind.INSTRUCTION_CORRECTION else None
    phrase = _pick(scene.openings(kind, target, named), u[3])
    text = instruction(_pick(verbs, u[0]), phrase)
    return extend(text, _correction(scene, kind, phrase, target, touched, negations, u[_DRAWS_PER_OPENING:]))


def _correction(
    scene: _Scene, kind: Kind, phrase: Phrase, target: int, touched: int, negations: bool, v: np.ndarray
) -> str:
    """One correction after the arm acted on ``touched``, singling out ``target``, chosen by the draws ``v``
    (form, beginning words, phrase)."""
    form = _pick(correction_forms(negations), v[0])
    if form is CorrectionForm.NEGATION:
        negated = scene.negations(kind, phrase, target, touched)
        if negated:
            return correction(BEGINNING_WORDS[form][0], _pick(negated, v[2]))
        form = _pick(NAMING_FORMS, v[1])
    return correction(_pick(BEGINNING_WORDS[form], v[1]), _pick(scene.naming(kind, phrase, target), v[2]))


@dataclass(frozen=True)
class SentencePool:
    """Relabelling sentences for one episode, as token ids.

    ``plain``: uint8 [rows, n_objects, L], by target. ``corrected``: uint8 [rows, n_objects, n_objects, L],
    by target and touched object (padding where the two are one). ``identifiable``: bool [n_objects]; where it is
    false (an object with an identical twin) no sentence can name the object and its rows are padding.
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
    holdout: Holdout = NOTHING_HELD_OUT,
) -> SentencePool:
    """``rows`` plain sentences for every identifiable object of the scene, and ``rows`` corrected ones for
    every pair of an identifiable target and another object the arm may have acted on first; none of them
    says a word ``holdout`` keeps out of training."""
    verbs = TASK_VERBS[task]
    n = len(objects)
    scene = _Scene(objects, holdout)
    plain = np.zeros((rows, n, vocabulary.max_length), dtype=np.uint8)
    corrected = np.zeros((rows, n, n, vocabulary.max_length), dtype=np.uint8)
    identifiable = np.array([bool(scene.identifying(k)) for k in range(n)], dtype=bool)
    for k in np.flatnonzero(identifiable):
        draws = rng.random((rows, n, _DRAWS))
        plain[:, k] = vocabulary.encode_many(plain_sentence(verbs, scene, k, u) for u in draws[:, k])
        for j in range(n):
            if j != k:
                texts = (corrected_sentence(verbs, scene, k, j, negations, u) for u in draws[:, j])
                corrected[:, k, j] = vocabulary.encode_many(texts)
    return SentencePool(plain, corrected, identifiable)
