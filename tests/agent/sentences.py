"""An independent reader of the instructor's sentences, for checking what relabelled sentences mean.

It parses a sentence by the grammar of the paper's appendix and resolves which objects of a scene it
designates, without using the relabelling code's own reasoning.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from lanrocli.core.choices import CorrectionForm
from lanrocli.language import (
    BEGINNING_WORDS,
    COLOURS,
    RARE_WORD_COLOURS,
    SHAPE_WORDS,
    TASK_VERBS,
    ObjectProps,
)

COLOUR_OF = {c: c for c in COLOURS} | RARE_WORD_COLOURS
SHAPE_OF = {word: shape for shape, words in SHAPE_WORDS.items() for word in words}
BEGINNING_OF = {words: kind for kind, all_words in BEGINNING_WORDS.items() for words in all_words}


@dataclass(frozen=True)
class Noun:
    colour: str | None
    shape: str | None
    rare: bool

    def fits(self, obj: ObjectProps, knows_rare: bool = True) -> bool:
        """Does the phrase describe ``obj``? A listener who does not know rare words hears any colour."""
        colour_known = knows_rare or not self.rare
        return (not colour_known or self.colour in (None, obj.colour)) and self.shape in (None, obj.shape)


@dataclass(frozen=True)
class Parsed:
    verb: str
    noun: Noun
    beginning: CorrectionForm | None
    corrected: Noun | None


class NotInGrammar(ValueError):
    pass


def _noun(words: list[str], allow_rare: bool) -> Noun:
    if len(words) != 2:
        raise NotInGrammar(f"a noun phrase has two words, got {words}")
    first, second = words
    if second == "object":
        if first in SHAPE_OF:
            return Noun(None, SHAPE_OF[first], False)
        if first in COLOUR_OF:
            rare = first not in COLOURS
            if rare and not allow_rare:
                raise NotInGrammar(f"rare word {first!r} in a correction")
            return Noun(COLOUR_OF[first], None, rare)
        raise NotInGrammar(f"{first!r} is neither colour nor shape")
    if first not in COLOUR_OF or second not in SHAPE_OF:
        raise NotInGrammar(f"{words} is not COLOUR SHAPE")
    rare = first not in COLOURS
    if rare and not allow_rare:
        raise NotInGrammar(f"rare word {first!r} in a correction")
    return Noun(COLOUR_OF[first], SHAPE_OF[second], rare)


def parse(text: str, task: str) -> Parsed:
    """``TASKVERB the OBJECT [BEGINNING the OBJECT]``, or :class:`NotInGrammar`."""
    words = text.split()
    if len(words) < 4 or words[0] not in TASK_VERBS[task] or words[1] != "the":
        raise NotInGrammar(f"{text!r} does not start with a {task} verb and 'the'")
    noun = _noun(words[2:4], allow_rare=True)
    rest = words[4:]
    if not rest:
        return Parsed(words[0], noun, None, None)
    if "the" not in rest:
        raise NotInGrammar(f"{text!r}: correction without 'the'")
    cut = rest.index("the")
    beginning = " ".join(rest[:cut])
    if beginning not in BEGINNING_OF:
        raise NotInGrammar(f"{beginning!r} is not a correction beginning")
    return Parsed(words[0], noun, BEGINNING_OF[beginning], _noun(rest[cut + 1 :], allow_rare=False))


def referents(parsed: Parsed, objects: Sequence[ObjectProps], knows_rare: bool = True) -> list[int]:
    """Indices of the objects the sentence designates. A correction works on the objects the instruction
    left open: an excuse or edit keeps those its phrase fits, a negation drops those its phrase fits. A
    correction that leaves none of them retracts the instruction ("push the red cube actually the blue
    cube", "push the red cube not the red cube") and works on every object instead."""
    fits = [i for i, o in enumerate(objects) if parsed.noun.fits(o, knows_rare)]
    if parsed.beginning is None:
        return fits
    assert parsed.corrected is not None
    corrected = parsed.corrected
    if parsed.beginning is CorrectionForm.NEGATION:
        kept = [i for i in fits if not corrected.fits(objects[i])]
        return kept or [i for i, o in enumerate(objects) if not corrected.fits(o)]
    kept = [i for i in fits if corrected.fits(objects[i])]
    return kept or [i for i, o in enumerate(objects) if corrected.fits(o)]
