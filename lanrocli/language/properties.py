"""The objects' properties: the words the instructor may use for each (a task's verbs are its class's).

Canonical names (``"red"``, ``"cuboid"``) identify a property everywhere in the code; the
words are only what the instructor says. Keeping both apart lets the instructor vary its wording
(synonyms, rare words) while tasks, scenes and relabelling reason about canonical properties.
"""

from __future__ import annotations

from dataclasses import dataclass

COLOURS: tuple[str, ...] = ("red", "green", "blue", "yellow", "purple", "orange", "pink", "cyan", "brown")

# Rare words per colour for the "lack of common ground" case: words that name the colour but that an agent
# trained on the common words has likely never read. Two per colour, so a curriculum can hold one of them
# out of training (its ``holdout.common_ground``) and test what the paper means: a word the agent does not
# share, resolved by a correction.
RARE_COLOUR_WORDS: dict[str, tuple[str, ...]] = {
    "red": ("scarlet", "crimson"),
    "green": ("emerald", "jade"),
    "blue": ("azure", "cobalt"),
    "yellow": ("lemon", "amber"),
    "purple": ("violet", "lilac"),
    "orange": ("tangerine", "apricot"),
    "pink": ("rose", "salmon"),
    "cyan": ("turquoise", "teal"),
    "brown": ("chestnut", "umber"),
}

RARE_WORD_COLOURS: dict[str, str] = {word: colour for colour, words in RARE_COLOUR_WORDS.items() for word in words}
"""Each rare word to the colour it names."""

SHAPES: tuple[str, ...] = ("cube", "cuboid", "cylinder")

# Word classes from the paper's appendix: every word of a class names the same shape.
SHAPE_WORDS: dict[str, tuple[str, ...]] = {
    "cube": ("cube", "box", "block"),
    "cuboid": ("cuboid", "brick", "oblong"),
    "cylinder": ("cylinder", "barrel", "tophat"),
}

WORD_SHAPES: dict[str, str] = {word: shape for shape, words in SHAPE_WORDS.items() for word in words}
"""Each shape word to the shape it names."""


@dataclass(frozen=True, order=True)
class ObjectProps:
    """What the instructor knows about one object on the table: its colour and its shape."""

    colour: str
    shape: str

    def __post_init__(self) -> None:
        if self.colour not in COLOURS:
            raise ValueError(f"unknown colour {self.colour!r}; expected one of {', '.join(COLOURS)}")
        if self.shape not in SHAPES:
            raise ValueError(f"unknown shape {self.shape!r}; expected one of {', '.join(SHAPES)}")

    @property
    def indices(self) -> tuple[int, int]:
        """The colour's index in ``COLOURS`` and the shape's in ``SHAPES``: the object as numbers."""
        return COLOURS.index(self.colour), SHAPES.index(self.shape)

    @classmethod
    def from_indices(cls, colour: int, shape: int) -> ObjectProps:
        return cls(COLOURS[colour], SHAPES[shape])

    def shared_properties(self, other: ObjectProps) -> int:
        """How many properties (0, 1 or 2) this object has in common with ``other``."""
        return int(self.colour == other.colour) + int(self.shape == other.shape)
