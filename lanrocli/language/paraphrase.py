"""Phrasings the grammar never speaks, for the paraphrase split: how a person types a correction.

A person writes "wrong one, i meant the green cube", "the green cube not the red one" or "no, the other
cube", and may call a cube a crate or ask the arm to shove it. The paraphrase split speaks its corrections
this way, and some of its instructions with a verb training never heard, so that its drop from the same
episodes spoken in the grammar (its control) is the price of the phrasing alone. Each form is one line of
:data:`PARAPHRASES`; a new form is a new line.

A template's slots are filled from the scene by the rule the grammar's own corrections follow
(:mod:`lanrocli.language.dialogue`), so every paraphrase singles out the goal among the objects a listener
still considers:

- ``{goal}``: a phrase that fits the goal and no other considered object (an excuse's or an edit's);
- ``{negated}``: a phrase that fits the object acted on and leaves the goal alone among the considered
  ones (a negation's);
- ``{touched}``: a phrase that fits the object acted on and not the goal, beside ``{goal}``, which already
  singles the goal out;
- ``{goal_synonym}``: ``{goal}`` with its shape word replaced by one training never heard;
- ``{other}``: ``one`` where the goal is the only considered object besides the one acted on, or a shape
  word where the goal is the only other considered object of that shape, which the one acted on shares.

Punctuation is left out, as the grammar leaves it out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from lanrocli.core.choices import CorrectionForm
from lanrocli.language.dialogue import naming_phrases, negation_phrases
from lanrocli.language.grammar import NAMING_FORMS, Form, Phrase, object_phrases, pick
from lanrocli.language.properties import SHAPE_WORDS, ObjectProps

SYNONYM_SHAPE_WORDS: dict[str, tuple[str, ...]] = {
    "cube": ("crate",),
    "cuboid": ("slab",),
    "cylinder": ("can",),
}
"""Shape words training never hears, each naming the shape it stands under."""

OTHER_ONE = "one"
"""The ``{other}`` slot's word where no shape is needed: "no the other one"."""


@dataclass(frozen=True)
class Paraphrase:
    """One correction form of the split: its template and the grammar forms it may stand in for (the form
    a record counts it under)."""

    name: str
    template: str
    stands_for: tuple[CorrectionForm, ...]


EVERY_FORM = tuple(CorrectionForm)

PARAPHRASES: tuple[Paraphrase, ...] = (
    Paraphrase("wrong one", "wrong one i meant the {goal}", NAMING_FORMS),
    Paraphrase("i said", "i said the {goal}", NAMING_FORMS),
    Paraphrase("please", "the {goal} please", NAMING_FORMS),
    Paraphrase("wrong one, negated", "wrong one not the {negated}", (CorrectionForm.NEGATION,)),
    Paraphrase("negated, please", "not the {negated} please", (CorrectionForm.NEGATION,)),
    Paraphrase("object first", "the {goal} not the {touched}", EVERY_FORM),
    Paraphrase("i meant, object first", "i meant the {goal} not the {touched}", EVERY_FORM),
    Paraphrase("the other", "no the other {other}", EVERY_FORM),
    Paraphrase("shape synonym", "sorry the {goal_synonym}", NAMING_FORMS),
)
"""The split's correction forms: carrier words around a correction, the object before the negation, only
what differs ("the other"), and shape words never heard."""


@dataclass(frozen=True)
class Referents:
    """What a correction refers to: the objects, the goal, the object acted on and the objects a listener
    still considers; ``allowed`` drops the phrases the run holds out of corrections, so that the split tests
    its phrasing and nothing else held out."""

    objects: Sequence[ObjectProps]
    goal: int
    touched: int
    considered: set[int]
    allowed: Callable[[list[Phrase]], list[Phrase]] = lambda phrases: phrases


def _synonym(phrase: Phrase) -> list[str]:
    """``phrase``'s words with its shape word replaced by each never-heard synonym (none without a shape)."""
    if phrase.shape is None or phrase.form is not Form.COLOUR_SHAPE:
        return []
    colour_words = phrase.words.split()[:-1]
    return [" ".join([*colour_words, word]) for word in SYNONYM_SHAPE_WORDS[phrase.shape]]


def _other_words(scene: Referents) -> list[str]:
    """The ``{other}`` slot's fillings that single out the goal; empty where none does."""
    objects, goal, touched = scene.objects, scene.goal, scene.touched
    rest = scene.considered - {touched}
    if touched not in scene.considered or goal not in rest:
        return []
    words = [OTHER_ONE] if rest == {goal} else []
    shape = objects[goal].shape
    same_shape = {i for i in rest if objects[i].shape == shape}
    if objects[touched].shape == shape and same_shape == {goal}:
        words.extend(w for w in SHAPE_WORDS[shape] if scene.allowed([_shape_phrase(shape, w)]))
    return words


def _shape_phrase(shape: str, word: str) -> Phrase:
    return Phrase(Form.SHAPE, None, shape, word)


def slot_fillings(scene: Referents) -> dict[str, list[str]]:
    """Each slot's possible words in ``scene``; an empty list where the slot cannot be filled truthfully."""
    goal_phrases = scene.allowed(naming_phrases(scene.objects, scene.goal, scene.considered))
    return {
        "goal": [p.words for p in goal_phrases],
        "negated": [
            p.words for p in scene.allowed(negation_phrases(scene.objects, scene.goal, scene.touched, scene.considered))
        ],
        "touched": [
            p.words
            for p in scene.allowed(object_phrases(scene.objects[scene.touched]))
            if not p.matches(scene.objects[scene.goal])
        ],
        "goal_synonym": [words for p in goal_phrases for words in _synonym(p)],
        "other": _other_words(scene),
    }


def _slots(template: str) -> list[str]:
    return [part.split("}")[0] for part in template.split("{")[1:]]


def _words(text: str) -> int:
    return len(text.split())


def _shortest(paraphrase: Paraphrase, fillings: dict[str, list[str]]) -> int:
    """The fewest words ``paraphrase`` can be spoken in: its own words and each slot's shortest filling."""
    slots = _slots(paraphrase.template)
    own = _words(paraphrase.template.format(**dict.fromkeys(slots, "")))
    return own + sum(min(_words(f) for f in fillings[slot]) for slot in slots)


def applicable(form: CorrectionForm, scene: Referents, max_words: int | None = None) -> list[Paraphrase]:
    """The paraphrases that may stand in for a correction of ``form`` in ``scene``: each slot fillable, in
    at most ``max_words`` words where given."""
    fillings = slot_fillings(scene)
    fit = [p for p in PARAPHRASES if form in p.stands_for and all(fillings[s] for s in _slots(p.template))]
    return fit if max_words is None else [p for p in fit if _shortest(p, fillings) <= max_words]


def paraphrase_correction(
    rng: np.random.Generator, form: CorrectionForm, scene: Referents, max_words: int | None = None
) -> tuple[str, str] | None:
    """A correction of ``form`` in a phrasing the grammar never speaks, in at most ``max_words`` words
    (the room an observation's sentence has left), and its paraphrase's name; None where no paraphrase
    fits (the grammar's correction is then spoken)."""
    options = applicable(form, scene, max_words)
    if not options:
        return None
    chosen = pick(rng, options)
    fillings = slot_fillings(scene)
    slots = _slots(chosen.template)
    room = (max_words if max_words is not None else 10**6) - _shortest(chosen, fillings)
    words: dict[str, str] = {}
    for slot in slots:
        least = min(_words(f) for f in fillings[slot])
        words[slot] = pick(rng, [f for f in fillings[slot] if _words(f) - least <= room])
        room -= _words(words[slot]) - least
    return chosen.template.format(**words), chosen.name
