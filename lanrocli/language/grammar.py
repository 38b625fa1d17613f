"""The instructor's grammar (the paper's appendix A): instructions, corrections and their extension.

    INSTRUCTION          ::= TASKVERB "the" OBJECT
    OBJECT               ::= COLOUR SHAPE | SHAPE "object" | COLOUR "object"
    EXTENDED INSTRUCTION ::= INSTRUCTION CORRECTION
    CORRECTION           ::= BEGINNING "the" OBJECT
    BEGINNING            ::= EXCUSE | NEGATION | EDIT
    EXCUSE               ::= "sorry" | "excuse me" | "no i meant" | "pardon"
    NEGATION             ::= "not"
    EDIT                 ::= "actually"

Sentences are lower case with single spaces and no punctuation. Rare colour words (the "lack of common
ground" case) may appear in instructions only: a correction exists to restore common ground, so it
always uses the common words.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from lanrocli.core.choices import CorrectionForm
from lanrocli.language.properties import (
    COLOURS,
    RARE_COLOUR_WORDS,
    SHAPE_WORDS,
    SHAPES,
    ObjectProps,
)
from lanrocli.tasks import TASK_VERBS, check_task

ARTICLE = "the"
OBJECT_WORD = "object"


class Form(StrEnum):
    """Which properties a noun phrase names."""

    COLOUR_SHAPE = "colour_shape"
    SHAPE = "shape"
    COLOUR = "colour"


BEGINNING_WORDS: dict[CorrectionForm, tuple[str, ...]] = {
    CorrectionForm.EXCUSE: ("sorry", "excuse me", "no i meant", "pardon"),
    CorrectionForm.NEGATION: ("not",),
    CorrectionForm.EDIT: ("actually",),
}
"""The words each form of correction begins with."""

NAMING_FORMS: tuple[CorrectionForm, ...] = (CorrectionForm.EXCUSE, CorrectionForm.EDIT)
"""The forms whose correction names the goal, replacing the instruction's object."""


def correction_forms(negations: bool) -> tuple[CorrectionForm, ...]:
    """The forms the instructor may use; the negation only where a stage allows it."""
    if negations:
        return tuple(CorrectionForm)
    return NAMING_FORMS


@dataclass(frozen=True)
class Phrase:
    """A noun phrase that names an object: the properties it names and the words that name them.

    ``colour``/``shape`` hold canonical property names (``None`` where the phrase leaves it open), so
    whether a phrase fits an object never depends on which synonym or rare word was spoken.
    """

    form: Form
    colour: str | None
    shape: str | None
    words: str
    rare: bool = False

    def matches(self, obj: ObjectProps) -> bool:
        """Does this phrase truthfully describe ``obj``?"""
        return (self.colour is None or self.colour == obj.colour) and (self.shape is None or self.shape == obj.shape)


def _colour_words(colour: str, rare: bool) -> tuple[tuple[str, bool], ...]:
    words = [(colour, False)]
    if rare:
        words.extend((word, True) for word in RARE_COLOUR_WORDS[colour])
    return tuple(words)


def object_phrases(obj: ObjectProps, rare: bool = False, forms: Sequence[Form] = tuple(Form)) -> list[Phrase]:
    """Every phrase of the given forms that truthfully describes ``obj`` (all synonyms, optionally rare words)."""
    phrases: list[Phrase] = []
    for form in forms:
        if form is Form.COLOUR_SHAPE:
            for cword, is_rare in _colour_words(obj.colour, rare):
                for sword in SHAPE_WORDS[obj.shape]:
                    phrases.append(Phrase(form, obj.colour, obj.shape, f"{cword} {sword}", is_rare))
        elif form is Form.SHAPE:
            for sword in SHAPE_WORDS[obj.shape]:
                phrases.append(Phrase(form, None, obj.shape, f"{sword} {OBJECT_WORD}"))
        else:
            for cword, is_rare in _colour_words(obj.colour, rare):
                phrases.append(Phrase(form, obj.colour, None, f"{cword} {OBJECT_WORD}", is_rare))
    return phrases


def all_phrases(rare: bool = False) -> list[Phrase]:
    """Every OBJECT production of the grammar, each once."""
    phrases: list[Phrase] = []
    for colour in COLOURS:
        for shape in SHAPES:
            phrases.extend(object_phrases(ObjectProps(colour, shape), rare, (Form.COLOUR_SHAPE,)))
    for shape in SHAPES:
        phrases.extend(object_phrases(ObjectProps(COLOURS[0], shape), rare, (Form.SHAPE,)))
    for colour in COLOURS:
        phrases.extend(object_phrases(ObjectProps(colour, SHAPES[0]), rare, (Form.COLOUR,)))
    return phrases


def identifying_phrases(target: ObjectProps, others: Sequence[ObjectProps], rare: bool = False) -> list[Phrase]:
    """Phrases that describe ``target`` and none of ``others``: a listener who knows the words finds it."""
    return [p for p in object_phrases(target, rare) if not any(p.matches(o) for o in others)]


def ambiguous_phrases(target: ObjectProps, others: Sequence[ObjectProps], rare: bool = False) -> list[Phrase]:
    """Phrases that describe ``target`` and at least one of ``others``: true, but not enough to choose."""
    return [p for p in object_phrases(target, rare) if any(p.matches(o) for o in others)]


def instruction(verb: str, phrase: Phrase) -> str:
    """``TASKVERB the OBJECT``."""
    return f"{verb} {ARTICLE} {phrase.words}"


def correction(beginning: str, phrase: Phrase) -> str:
    """``BEGINNING the OBJECT``."""
    return f"{beginning} {ARTICLE} {phrase.words}"


def extend(instruction_text: str, *corrections: str | None) -> str:
    """The goal after corrections: the instruction followed by each correction in the order spoken
    (g_l o g_ac, and on for a chain of them)."""
    return " ".join([instruction_text, *(c for c in corrections if c)])


@dataclass(frozen=True)
class Sentence:
    """One instructor utterance: an instruction and, in correction episodes, the correction appended to it."""

    instruction: str
    correction: str | None
    form: Form
    beginning: CorrectionForm | None = None

    @property
    def text(self) -> str:
        return extend(self.instruction, self.correction)


def all_instructions(task: str, rare: bool = False) -> Iterator[tuple[str, Form]]:
    """Every INSTRUCTION the grammar can speak for ``task``, with its form."""
    phrases = all_phrases(rare)
    for verb in TASK_VERBS[check_task(task)]:
        for phrase in phrases:
            yield instruction(verb, phrase), phrase.form


def all_corrections(negations: bool = False) -> Iterator[tuple[str, CorrectionForm]]:
    """Every CORRECTION the grammar can speak, with its form (never with rare words)."""
    phrases = all_phrases(rare=False)
    for kind in correction_forms(negations):
        for beginning in BEGINNING_WORDS[kind]:
            for phrase in phrases:
                yield correction(beginning, phrase), kind


def all_sentences(
    task: str, corrections: bool = False, negations: bool = False, rare: bool = False
) -> Iterator[Sentence]:
    """Every sentence: the instructions, or with ``corrections`` every EXTENDED INSTRUCTION."""
    if not corrections:
        for text, form in all_instructions(task, rare):
            yield Sentence(text, None, form)
        return
    corr = list(all_corrections(negations))
    for text, form in all_instructions(task, rare):
        for ctext, kind in corr:
            yield Sentence(text, ctext, form, kind)


def pick(rng: np.random.Generator, items: Sequence):  # type: ignore[no-untyped-def]
    """A uniform choice that keeps the element as it is (``rng.choice`` turns tuples and enums into arrays)."""
    return items[int(rng.integers(len(items)))]


def sample_phrase(rng: np.random.Generator, rare: bool = False) -> Phrase:
    """A random OBJECT: uniform over forms, then over the objects and words that form allows."""
    form = pick(rng, tuple(Form))
    obj = ObjectProps(pick(rng, COLOURS), pick(rng, SHAPES))
    return pick(rng, object_phrases(obj, rare, (form,)))


def sample_sentence(
    rng: np.random.Generator, task: str, corrections: bool = False, negations: bool = False, rare: bool = False
) -> Sentence:
    """A random sentence from the grammar, ignoring any scene: for inspecting what the instructor can say."""
    verb = pick(rng, TASK_VERBS[check_task(task)])
    phrase = sample_phrase(rng, rare)
    text = instruction(verb, phrase)
    if not corrections:
        return Sentence(text, None, phrase.form)
    kind = pick(rng, correction_forms(negations))
    ctext = correction(pick(rng, BEGINNING_WORDS[kind]), sample_phrase(rng, rare=False))
    return Sentence(text, ctext, phrase.form, kind)


def max_sentence_words(corrections: int = 1) -> int:
    """L: the most words an instruction extended by up to ``corrections`` corrections can have, over every
    task and option."""
    verb = max(len(v.split()) for verbs in TASK_VERBS.values() for v in verbs)
    phrase = max(len(p.words.split()) for p in all_phrases(rare=True))
    beginning = max(len(b.split()) for words in BEGINNING_WORDS.values() for b in words)
    return (verb + 1 + phrase) + corrections * (beginning + 1 + phrase)


def grammar_words() -> list[str]:
    """Every word any stage may speak: all tasks' verbs, all properties, rare words, all beginnings."""
    words: set[str] = {ARTICLE, OBJECT_WORD}
    for verbs in TASK_VERBS.values():
        for verb in verbs:
            words.update(verb.split())
    for phrase in all_phrases(rare=True):
        words.update(phrase.words.split())
    for beginnings in BEGINNING_WORDS.values():
        for beginning in beginnings:
            words.update(beginning.split())
    return sorted(words)


@dataclass(frozen=True)
class SentenceStats:
    """Counts over a set of sentences, for checking the grammar's size by hand."""

    sentences: int
    distinct: int
    by_form: dict[str, int]
    by_beginning: dict[str, int]


def sentence_stats(sentences: Iterator[Sentence] | Sequence[Sentence]) -> SentenceStats:
    """How many sentences, how many distinct, and how many of each instruction form and correction beginning."""
    total = 0
    texts: set[str] = set()
    by_form = {f.value: 0 for f in Form}
    by_beginning: dict[str, int] = {}
    for s in sentences:
        total += 1
        texts.add(s.text)
        by_form[s.form.value] += 1
        if s.beginning is not None:
            by_beginning[s.beginning.value] = by_beginning.get(s.beginning.value, 0) + 1
    return SentenceStats(total, len(texts), by_form, by_beginning)
