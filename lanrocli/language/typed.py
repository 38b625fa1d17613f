"""A sentence a person types, read the way the instructor builds its sentences (an instruction, then the
corrections appended to it): its words, what each clause says about an object, the objects the whole can
mean, and whether the grammar could have produced it. ``lanro play`` reads its lines here.

Pure Python, like the rest of the language package.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from lanrocli.core.choices import CorrectionForm
from lanrocli.language.grammar import BEGINNING_WORDS, all_corrections, all_instructions, extend
from lanrocli.language.properties import COLOURS, RARE_WORD_COLOURS, WORD_SHAPES, ObjectProps
from lanrocli.language.vocabulary import Vocabulary

COLOUR_OF_WORD: Mapping[str, str] = {**{c: c for c in COLOURS}, **RARE_WORD_COLOURS}
"""Every word that names a colour (common and rare), to the colour it names."""

NEGATION = BEGINNING_WORDS[CorrectionForm.NEGATION][0]

WORD = re.compile(r"[\w']+")


def words_of(line: str) -> tuple[str, ...]:
    """The words of a typed line as the grammar writes them: lower case, without punctuation, so "Sorry,
    the BLUE cube!" reads as the instructor's "sorry the blue cube"."""
    return tuple(WORD.findall(line.lower()))


@dataclass(frozen=True)
class Description:
    """What one clause says about its object: the colours and shapes its words name, and whether it is a
    negation ("not the red cube" rules an object out rather than naming the goal).

    Sets, not single values, so that a clause naming two colours fits no object instead of either, and one
    naming none (an unknown colour word, "the cube") leaves the colour open, as the grammar's ``<shape>
    object`` form does.
    """

    colours: frozenset[str]
    shapes: frozenset[str]
    negation: bool = False

    @classmethod
    def of(cls, words: Sequence[str], correction: bool = False) -> Description:
        return cls(
            frozenset(COLOUR_OF_WORD[w] for w in words if w in COLOUR_OF_WORD),
            frozenset(WORD_SHAPES[w] for w in words if w in WORD_SHAPES),
            correction and bool(words) and words[0] == NEGATION,
        )

    def matches(self, obj: ObjectProps) -> bool:
        return self.colours <= {obj.colour} and self.shapes <= {obj.shape}


@dataclass(frozen=True)
class Utterance:
    """What the person has said in an episode: the instruction, and the corrections appended to it, the
    last one ``correction`` and those before it ``earlier``."""

    instruction: tuple[str, ...]
    correction: tuple[str, ...] | None = None
    earlier: tuple[tuple[str, ...], ...] = ()

    @property
    def corrections(self) -> tuple[tuple[str, ...], ...]:
        return (*self.earlier, self.correction) if self.correction else ()

    @property
    def text(self) -> str:
        """The sentence the agent reads (g_l o g_ac, as the instructor extends its goal)."""
        return extend(" ".join(self.instruction), *(" ".join(c) for c in self.corrections))

    @property
    def length(self) -> int:
        return len(self.instruction) + sum(len(c) for c in self.corrections)

    def corrected(self, words: tuple[str, ...]) -> Utterance:
        return Utterance(self.instruction, words, self.corrections)

    def fitting(self, objects: Sequence[ObjectProps]) -> list[int]:
        """The indices of the objects the sentence can mean.

        The correction narrows what the instruction meant (an excuse or edit to the objects it names, a
        negation to those it does not name). When nothing of that is left, the correction retracts the
        instruction and applies to the whole table: that is how the instructor corrects an instruction that
        named the wrong object ("push the red cube" + "actually the blue cube", or "... not the red cube").
        """
        meant = {i for i, o in enumerate(objects) if Description.of(self.instruction).matches(o)}
        for words in self.corrections:  # each correction narrows what is left, as the instructor's chains do
            said = Description.of(words, correction=True)
            named = {i for i, o in enumerate(objects) if said.matches(o)}
            pools = (meant, set(range(len(objects))))
            meant = next((left for pool in pools if (left := pool - named if said.negation else pool & named)), set())
        return sorted(meant)


@dataclass(frozen=True)
class Grammar:
    """Every instruction of one task and every correction, to tell a person when a sentence is not one the
    instructor could have spoken (the agent may then misread it)."""

    task: str
    instructions: frozenset[str]
    corrections: frozenset[str]

    @classmethod
    def of(cls, task: str) -> Grammar:
        return cls(
            task,
            frozenset(text for text, _ in all_instructions(task, rare=True)),
            frozenset(text for text, _ in all_corrections(negations=True)),
        )

    def __contains__(self, utterance: object) -> bool:
        if not isinstance(utterance, Utterance):
            return False
        if " ".join(utterance.instruction) not in self.instructions:
            return False
        return all(" ".join(words) in self.corrections for words in utterance.corrections)


def unknown_words(words: Sequence[str], vocabulary: Vocabulary) -> list[str]:
    """The words the agent reads as ``<unk>``, each once, in the order typed."""
    return list(dict.fromkeys(w for w in words if w not in vocabulary))
