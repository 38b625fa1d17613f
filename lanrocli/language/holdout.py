"""What a curriculum keeps out of training, to test on afterwards: the generalisation splits.

A ``Holdout`` is plain data with the rules that follow from it. Training episodes (``split`` ``None``) never
contain what it holds out; the episodes of one split contain that split's part and nothing else held out, so
the drop from the in-distribution figure is the price of that one difference.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from lanrocli.core.choices import Split
from lanrocli.language.grammar import Phrase
from lanrocli.language.properties import (
    COLOURS,
    RARE_COLOUR_WORDS,
    RARE_WORD_COLOURS,
    SHAPE_WORDS,
    SHAPES,
    WORD_SHAPES,
    ObjectProps,
)


def parse_pair(text: str) -> ObjectProps:
    """``"red cylinder"`` as the object it names; a clear ValueError for anything else."""
    parts = text.split()
    if len(parts) != 2:
        raise ValueError(f"{text!r} is not a colour-shape pair: write a colour and a shape, such as 'red cylinder'")
    colour, shape = parts
    if colour not in COLOURS:
        raise ValueError(f"{text!r}: unknown colour {colour!r}; the colours are {', '.join(COLOURS)}")
    if shape not in SHAPES:
        raise ValueError(f"{text!r}: unknown shape {shape!r}; the shapes are {', '.join(SHAPES)}")
    return ObjectProps(colour, shape)


def _distinct(values: Sequence[Any], what: str) -> None:
    repeated = sorted({str(v) for v in values if values.count(v) > 1})
    if repeated:
        raise ValueError(f"{what} names {', '.join(repeated)} more than once")


@dataclass(frozen=True)
class Holdout:
    """What training never shows. Every part is optional; an empty ``Holdout`` holds nothing out.

    ``pairs``: colour-shape combinations never on the table in training (so never a goal nor named); the
    ``pairs`` split makes one of them the goal. ``correction_words``: shape words never used inside a
    correction in training (instructions still use them), one for each shape, so every correction of the
    ``correction_words`` split can use one. ``late_corrections``: the delays (first, last) of the
    ``late_corrections`` split's corrections; a curriculum checks they start after every stage's
    ``max_delay``. ``common_ground``: rare colour words never heard in training, at most one per colour,
    so each colour keeps a rare word to train on; the ``common_ground`` split's instructions use them.
    ``paraphrase``: whether a run tests on the ``paraphrase`` split, whose phrasings the grammar never
    speaks (:mod:`lanrocli.language.paraphrase`), so that training holds them out whatever this says.
    """

    pairs: tuple[ObjectProps, ...] = ()
    correction_words: tuple[str, ...] = ()
    late_corrections: tuple[int, int] | None = None
    common_ground: tuple[str, ...] = ()
    paraphrase: bool = False

    def __post_init__(self) -> None:
        pairs = tuple(parse_pair(p) if isinstance(p, str) else p for p in self.pairs)
        object.__setattr__(self, "pairs", pairs)
        _distinct(list(pairs), "pairs")
        words = self._known_words("correction_words", WORD_SHAPES, "shape words")
        if words:
            for shape in SHAPES:
                mine = [w for w in words if WORD_SHAPES[w] == shape]
                if len(mine) != 1:
                    raise ValueError(
                        f"correction_words needs exactly one word for each shape (so every correction of the split "
                        f"can use one and training keeps the others), and has {len(mine)} for {shape} "
                        f"(its words: {', '.join(SHAPE_WORDS[shape])})"
                    )
        if self.late_corrections is not None:
            first, last = (int(d) for d in self.late_corrections)
            if not 0 < first <= last:
                raise ValueError(f"late_corrections is [first, last] delay with 0 < first <= last, got {[first, last]}")
            object.__setattr__(self, "late_corrections", (first, last))
        rare = self._known_words("common_ground", RARE_WORD_COLOURS, "rare colour words")
        for colour, options in RARE_COLOUR_WORDS.items():
            if all(w in rare for w in options):
                raise ValueError(
                    f"common_ground holds out every rare word for {colour} ({', '.join(options)}); keep one "
                    "for training's common-ground episodes"
                )

    def _known_words(self, key: str, known: Mapping[str, str], what: str) -> tuple[str, ...]:
        """The words of field ``key`` as a tuple, each once and each one of ``known``, or a ValueError."""
        words = tuple(getattr(self, key))
        object.__setattr__(self, key, words)
        _distinct(list(words), key)
        unknown = [w for w in words if w not in known]
        if unknown:
            raise ValueError(
                f"{key} holds out {what}, and {', '.join(map(repr, unknown))} is none; "
                f"the {what} are {', '.join(known)}"
            )
        return words

    @property
    def splits(self) -> tuple[Split, ...]:
        """The splits this holdout defines, in the order of ``Split``."""
        held = {
            Split.PAIRS: bool(self.pairs),
            Split.CORRECTION_WORDS: bool(self.correction_words),
            Split.LATE_CORRECTIONS: self.late_corrections is not None,
            Split.COMMON_GROUND: bool(self.common_ground),
            Split.PARAPHRASE: self.paraphrase,
        }
        return tuple(split for split in Split if held[split])

    def check_split(self, split: Split | None) -> None:
        """Refuse a split this holdout kept nothing out for; the paraphrase split is always there, since no
        run ever heard its phrasings."""
        if split is not None and split is not Split.PARAPHRASE and split not in self.splits:
            raise ValueError(
                f"split {split.value!r} needs the holdout to hold something out for it; it holds {self.describe()}"
            )

    # -- the rules, for training (``split`` None) and for each split ---------------------------------------

    def goals(self, catalogue: Iterable[ObjectProps], split: Split | None) -> list[ObjectProps]:
        """The objects that may be the goal: never a held-out pair in training, always one in ``pairs``."""
        if split is Split.PAIRS:
            return [o for o in catalogue if o in self.pairs]
        return [o for o in catalogue if o not in self.pairs]

    def others(self, catalogue: Iterable[ObjectProps]) -> list[ObjectProps]:
        """The objects that may lie beside the goal: never a held-out pair, in training or any split."""
        return [o for o in catalogue if o not in self.pairs]

    def correction_phrases(self, phrases: Iterable[Phrase], split: Split | None) -> list[Phrase]:
        """The phrases a correction may use: none with a held-out word in training, only such in the split."""
        wanted = split is Split.CORRECTION_WORDS
        return [p for p in phrases if self._holds_out(p.words.split(), self.correction_words) == wanted]

    def instruction_phrases(self, phrases: Iterable[Phrase], split: Split | None) -> list[Phrase]:
        """The phrases an instruction may use: no held-out rare word in training; in ``common_ground``,
        rare phrases only with one."""
        if split is Split.COMMON_GROUND:
            return [p for p in phrases if not p.rare or self._holds_out(p.words.split(), self.common_ground)]
        return [p for p in phrases if not self._holds_out(p.words.split(), self.common_ground)]

    def delays(self, max_delay: int, split: Split | None) -> tuple[int, int]:
        """The range (first, last) of steps a correction waits after the mistake."""
        if split is Split.LATE_CORRECTIONS and self.late_corrections is not None:
            return self.late_corrections
        return 0, max_delay

    @staticmethod
    def _holds_out(words: Iterable[str], held: Sequence[str]) -> bool:
        return any(w in held for w in words)

    # -- as data ---------------------------------------------------------------------------------------------

    def describe(self) -> str:
        """One line, as error messages and reports name it."""
        data = self.to_dict()
        parts = []
        for split in self.splits:
            value = data[split.value]
            if split is Split.PARAPHRASE:
                parts.append(split.value)
            elif split is Split.LATE_CORRECTIONS:
                parts.append(f"{split.value}: delays {value[0]} to {value[1]}")
            else:
                parts.append(f"{split.value}: {', '.join(value)}")
        return "; ".join(parts) if parts else "nothing"

    def to_dict(self) -> dict[str, Any]:
        return {
            "pairs": [f"{o.colour} {o.shape}" for o in self.pairs],
            "correction_words": list(self.correction_words),
            "late_corrections": None if self.late_corrections is None else list(self.late_corrections),
            "common_ground": list(self.common_ground),
            "paraphrase": self.paraphrase,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None) -> Holdout:
        data = data or {}
        late = data.get("late_corrections")
        return cls(
            tuple(data.get("pairs", ())),
            tuple(data.get("correction_words", ())),
            None if late is None else (int(late[0]), int(late[1])),
            tuple(data.get("common_ground", ())),
            bool(data.get("paraphrase", False)),
        )


NOTHING_HELD_OUT = Holdout()
"""The holdout of a run that declares none: every episode may contain anything."""
