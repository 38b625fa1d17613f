"""``EnvSettings``: every setting of a ``LanroEnv`` besides its task, in the one place that checks them.

The curriculum's ``env:`` schema and the options of ``lanro eval`` are generated from these fields (their
types, defaults and ``help``), so a new environment setting is one new field here. A field's ``help``
metadata is what the command line shows; its check is :meth:`EnvSettings.__post_init__` with every other
setting left at its default, which is how the curriculum places a problem at the key that has it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from lanrocli.core.choices import Kind, Mode
from lanrocli.envs.instructor import InstructorSettings
from lanrocli.tasks import TASKS, task_class

PLAIN_LIMIT = 50
"""Steps of an episode without corrections."""
CORRECTION_LIMIT = 100
"""Steps of an episode when corrections may be spoken: the arm needs time to recover from its mistake."""


def _help(text: str, option: bool = True) -> dict[str, Any]:
    """A field's metadata: its ``help``, and whether commands that run episodes take it as an option
    (``False`` for a setting only training's collection acts on)."""
    return {"help": text, "option": option}


@dataclass(frozen=True)
class EnvSettings:
    """How a stage's episodes are drawn: objects, mode, the instructor's corrections, episode length, starts."""

    objects: int = field(default=2, metadata=_help("Objects on the table (2 or 3)."))
    mode: Mode = field(default=Mode.COLOUR, metadata=_help("Which properties vary between objects."))
    correction_rate: float = field(
        default=0.0, metadata=_help("Share of correction episodes, within [0, 1] (0: plain instructions).")
    )
    negations: bool = field(default=False, metadata=_help("Allow negating corrections ('not the red cube')."))
    negation_rate: float | None = field(
        default=None,
        metadata=_help(
            "Share of spoken corrections that are negations, where one can single out the goal (needs "
            "negations; default: the forms drawn uniformly, a third negations)."
        ),
    )
    max_delay: int = field(default=0, metadata=_help("Corrections arrive 0..MAX_DELAY steps after the mistake."))
    max_corrections: int = field(
        default=1,
        metadata=_help(
            "Most corrections per episode: while the arm acts on yet another wrong object, the instructor "
            "corrects again, each correction appended to the sentence (default 1, the paper's)."
        ),
    )
    rare_words: bool = field(default=False, metadata=_help("Allow rare colour words (the common-ground case)."))
    kinds: tuple[Kind, ...] | None = field(
        default=None,
        metadata=_help(f"Kinds of correction, comma-separated, of {', '.join(Kind)} (default: all)."),
    )
    max_episode_steps: int | None = field(
        default=None,
        metadata=_help(f"Steps per episode (default: {PLAIN_LIMIT}, or {CORRECTION_LIMIT} with corrections)."),
    )
    random_start: float = field(
        default=0.0,
        metadata=_help(
            "Share of episodes that start with the hand at a random point near the table, clear of the "
            "objects, instead of the neutral pose (for training; evaluation starts from the neutral pose)."
        ),
    )
    object_start: float = field(
        default=0.0,
        metadata=_help(
            "Share of episodes that start with the open hand around a random object, at the height of its "
            "centre (grasp and lift; for training, like random_start, which it adds to: the two sum to at most 1)."
        ),
    )
    mistake_start: float = field(
        default=0.0,
        metadata=_help(
            "Share of episodes that start after the scripted oracle has done the task on a random wrong object "
            "(for training, or with lanro eval as a probe of the recovery): the state in which the instructor "
            "corrects, drawn on top of the arm's start."
        ),
    )

    questions: int = field(
        default=0,
        metadata=_help(
            "Most times per episode the agent may ask 'which one?' (0: never). The instructor's answer is "
            "appended to the sentence and takes one of max_corrections' places; actions then carry one more "
            "number, which asks when above 0."
        ),
    )
    question_penalty: float = field(
        default=0.0, metadata=_help("Reward taken off for each question asked (at least 0).")
    )
    question_steps: int = field(
        default=1,
        metadata=_help(
            "Steps a question takes: the arm holds still while the episode's clock runs (0: it takes no time; "
            "then question_penalty must be above 0, so that asking is never free)."
        ),
    )

    def __post_init__(self) -> None:
        if isinstance(self.objects, bool) or self.objects not in (2, 3):
            raise ValueError(f"objects must be 2 or 3, got {self.objects!r}")
        try:
            object.__setattr__(self, "mode", Mode(self.mode))
        except ValueError:
            raise ValueError(f"mode must be one of {', '.join(Mode)}, got {self.mode!r}") from None
        if self.max_episode_steps is not None and self.max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be positive, got {self.max_episode_steps}")
        if not 0.0 <= self.random_start <= 1.0:
            raise ValueError(f"random_start must be a probability within [0, 1], got {self.random_start}")
        if not 0.0 <= self.mistake_start <= 1.0:
            raise ValueError(f"mistake_start must be a probability within [0, 1], got {self.mistake_start}")
        if not 0.0 <= self.object_start <= 1.0 - self.random_start:
            raise ValueError(
                f"object_start must be within [0, 1 - random_start] = [0, {1.0 - self.random_start:g}] (the two "
                f"shares split the episodes), got {self.object_start}"
            )
        if not self.question_penalty >= 0.0:
            raise ValueError(f"question_penalty must be at least 0, got {self.question_penalty}")
        if isinstance(self.question_steps, bool) or not isinstance(self.question_steps, int) or self.question_steps < 0:
            raise ValueError(f"question_steps must be a whole number of at least 0, got {self.question_steps!r}")
        if self.questions and self.question_steps == 0 and self.question_penalty == 0.0:
            raise ValueError(
                "a question that takes no step and costs no reward is free, so an agent would ask every time: "
                "set question_steps above 0 or question_penalty above 0"
            )
        instructor = self.instructor  # the instructor checks its own settings, across fields too
        object.__setattr__(self, "kinds", None if self.kinds is None else instructor.kinds)

    @property
    def instructor(self) -> InstructorSettings:
        return InstructorSettings(
            correction_rate=self.correction_rate,
            negations=self.negations,
            negation_rate=self.negation_rate,
            max_delay=self.max_delay,
            max_corrections=self.max_corrections,
            questions=self.questions,
            rare_words=self.rare_words,
            kinds=tuple(Kind) if self.kinds is None else tuple(self.kinds),
        )

    @property
    def episode_limit(self) -> int:
        """Steps after which an episode is truncated."""
        if self.max_episode_steps is not None:
            return self.max_episode_steps
        return CORRECTION_LIMIT if self.correction_rate > 0 else PLAIN_LIMIT

    def for_evaluation(self, correction_rate: float | None = None) -> EnvSettings:
        """These settings as evaluation uses them: every episode starts from the neutral pose and the agent
        acts in all of them (random, object and mistake starts are for training), so
        success is comparable across runs and curricula.
        ``correction_rate``, where given, replaces a non-zero share of correction episodes; settings without
        corrections keep none, since their episodes are not built to hold one."""
        training_only = ("random_start", "object_start", "mistake_start")
        changes: dict[str, Any] = dict.fromkeys(training_only, 0.0)
        if correction_rate is not None and self.correction_rate > 0:
            changes["correction_rate"] = correction_rate
        return dataclasses.replace(self, **changes)

    def check_task(self, task: str) -> None:
        """The settings that only some tasks accept: object starts need a gripper to open."""
        if self.object_start > 0.0 and not task_class(task).gripper:
            grippers = " or ".join(name for name in TASKS if task_class(name).gripper)
            raise ValueError(
                f"object_start is {self.object_start:g}, but it needs a task with a gripper ({grippers}): "
                f"{task} keeps its fingers closed; leave object_start at 0"
            )

    def replace(self, **changes: Any) -> EnvSettings:
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON and YAML: enums as their values, ``kinds`` as a list."""
        data = dataclasses.asdict(self)
        data["mode"] = self.mode.value
        data["kinds"] = None if self.kinds is None else [kind.value for kind in self.kinds]
        return data
