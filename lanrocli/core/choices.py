"""The named choices every layer shares: scene modes, kinds and forms of correction, the sentence shown,
the devices lanro runs on.

One enum each, read alike by the environment, the curriculum schema (pydantic), the command line (typer)
and the reports, so a new value is added here once; the task names come from the task classes
(``lanrocli.tasks.Task``). Each is a ``StrEnum``: its members are their values as strings (equal, hashed, printed
and written to JSON as them), which is what files and the command line carry.
"""

from __future__ import annotations

import re
from enum import StrEnum


class Mode(StrEnum):
    """Which properties vary between the objects of a scene."""

    COLOUR = "colour"
    """Cubes in the nine colours."""
    SHAPE = "shape"
    """The three shapes in three colours."""
    COLOUR_SHAPE = "colour_shape"
    """The three shapes in the nine colours."""


class Kind(StrEnum):
    """The misunderstanding a correction episode is built around."""

    AMBIGUITY = "ambiguity"
    COMMON_GROUND = "common_ground"
    INSTRUCTION_CORRECTION = "instruction_correction"
    WRONG_OBJECT = "wrong_object"


class CorrectionForm(StrEnum):
    """How a correction begins, which decides how it changes the goal: an excuse ("sorry the ...", "no i
    meant the ...") and an edit ("actually the ...") name the goal; a negation ("not the ...") rules out
    the object the arm acted on and leaves the goal as the one candidate. The order is the instructor's."""

    EXCUSE = "excuse"
    NEGATION = "negation"
    EDIT = "edit"


class Split(StrEnum):
    """A generalisation split: episodes built from what a curriculum's ``holdout`` kept out of training,
    each testing one thing the agent can only have understood, not memorised (docs/generalisation.md)."""

    PAIRS = "pairs"
    """The goal is a colour-shape combination never on the table in training."""
    CORRECTION_WORDS = "correction_words"
    """Every correction uses a shape word heard in instructions only, never inside a correction."""
    LATE_CORRECTIONS = "late_corrections"
    """Corrections arrive later after the mistake than any in training."""
    COMMON_GROUND = "common_ground"
    """The instruction's rare colour word was never heard in training."""
    PARAPHRASE = "paraphrase"
    """Corrections phrased as the grammar never phrases them, some instructions with a verb never heard."""


class ActingAttention(StrEnum):
    """How an agent with object attention reads the scene when it acts deterministically
    (``SACSettings.acting_attention`` says why one would choose either)."""

    SOFT = "soft"
    """The attention-weighted mix of the objects, as in training."""
    ARGMAX = "argmax"
    """The one object the attention weighs most."""


class Instruction(StrEnum):
    """Which sentence the agent reads during an episode: the check that it follows language at all.

    ``true`` is the instructor's sentence; ``blank`` is all padding, so an agent that reads language falls to
    about chance among the objects; ``other`` names another object on the table, and the episode is won
    when the task holds for that object, so an agent that reads language does about as well as with
    ``true``. A policy that scores high on ``blank`` or low on ``other`` ignores its instruction.
    """

    TRUE = "true"
    BLANK = "blank"
    OTHER = "other"


DEVICES = re.compile(r"cpu|cuda(:\d+)?")
"""The devices lanro runs on, by the names torch gives them: ``cpu``, ``cuda`` and ``cuda:N``."""


def check_device(name: str) -> None:
    """Refuse a device name lanro does not run on, with the choices. It needs no torch, so every command
    refuses a bad ``--device`` before anything loads, whether or not it would use the device."""
    if DEVICES.fullmatch(name) is None:
        raise ValueError(f"--device {name!r} is not a device lanro runs on; use cpu, cuda or cuda:N")
