"""What one episode came to, success rates with their intervals, and the registry of the figures every
tool reports.

Every success rate reported is one ``Figure`` of the registry ``FIGURES``: the columns of ``metrics.csv``,
``EvaluationReport.metrics`` and TensorBoard's figures are generated from it, and the tables and ``lanro
report`` read their figures through it. A new figure is one entry: ``FIGURES.register(Figure(...))`` (for a
while: ``with FIGURES.registered(...)``); every name derived below is read from the registry each time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from lanrocli.core.choices import CorrectionForm, Kind
from lanrocli.core.registry import Live, Registry
from lanrocli.envs.instructor import MAX_CORRECTIONS

JUDGED = 30
"""Spoken corrections of one kind or form below which its success is shown but not judged: with fewer, its
95% interval spans more than about 35 points."""

PLAIN = "plain"
"""The phase of an episode before any correction was spoken; after one, the phase is the correction's form."""
PHASES = (PLAIN, *(form.value for form in CorrectionForm))
"""The phases over which the attention on the goal is averaged, in the order tables show them."""

ATTENTION = "attention_on_goal"
"""Key of the attention on the goal in records, and the stem of its columns (``attention_on_goal_plain``)."""


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95% Wilson score interval: unlike the normal approximation it stays inside [0, 1] for small n."""
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


@dataclass(frozen=True)
class EpisodeResult:
    success: bool
    length: int
    challenge: Kind | None
    """The misunderstanding the episode was set up with (a correction episode), or None."""
    form: CorrectionForm | None
    """The form of the correction spoken last, or None where none was spoken."""
    returned: float
    attention: Mapping[str, tuple[float, int]] = field(default_factory=dict)
    """Per phase (``PHASES``) the episode went through: the sum over its steps of the share of attention on
    the goal, and the number of those steps. Empty for a policy without attention."""
    corrections: int = 0
    """How many corrections were spoken (more than one only where a stage allows chains of them)."""
    named_first: bool = False
    """Whether the first object the task's condition held for was the one the sentence names (the goal, or
    the object an ``other`` sentence names); False where it held for none. Success alone cannot tell an arm
    that read its sentence from one that moves on to the next object after a wrong one."""
    phrasing: str | None = None
    """The paraphrase the last correction was spoken in (the paraphrase split), None for the grammar's."""
    answers: tuple[str, ...] = ()
    """The instructor's answers to the policy's questions, in order: one per question asked."""
    asked_at: tuple[int, ...] = ()
    """The step at which each question was asked (0: before the arm's first move)."""
    wrong_objects: int = 0
    """How many times the task's condition came to hold for an object other than the goal: the arm acting
    on an object nobody meant."""
    fits: int = 1
    """How many objects the instruction may mean to a listener who knows only the common words."""

    @property
    def questions(self) -> int:
        return len(self.answers)

    @property
    def corrected(self) -> bool:
        """Whether a correction was spoken: derived from the form, so the forms split the corrected episodes."""
        return self.form is not None

    @property
    def negation(self) -> bool:
        return self.form is CorrectionForm.NEGATION


@dataclass(frozen=True)
class Rate:
    episodes: int
    successes: int

    @property
    def success(self) -> float:
        return self.successes / self.episodes if self.episodes else float("nan")

    @property
    def interval(self) -> tuple[float, float]:
        return wilson_interval(self.successes, self.episodes)

    @property
    def value(self) -> float | None:
        """The success rate, or None without episodes (where ``success`` is NaN)."""
        return self.success if self.episodes else None

    @property
    def judged(self) -> bool:
        """Whether a rate of one kind or form rests on enough episodes to be judged (``JUDGED``)."""
        return self.episodes >= JUDGED

    def as_dict(self) -> dict[str, Any]:
        return {"episodes": self.episodes, "success": self.value, "ci": list(self.interval)}


def _rate(results: Sequence[EpisodeResult]) -> Rate:
    return Rate(len(results), sum(r.success for r in results))


@dataclass(frozen=True)
class Figure:
    """One success rate that every tool reports alike: the episodes it counts, its two columns of
    ``metrics.csv``, its words in tables, and where an ``EvaluationReport.as_dict`` record keeps it."""

    name: str
    """Column of the success rate."""
    count: str
    """Column of the number of episodes it counts."""
    label: str
    counts: Callable[[EpisodeResult], bool]
    where: tuple[str, ...]
    """Keys leading to the mapping of a record that holds its episodes and success."""
    keys: tuple[str, str] = ("episodes", "success")
    """The keys of the episodes and the success in that mapping."""
    split: bool = False
    """A share of the spoken corrections (one kind or one form), judged only from ``JUDGED`` episodes on."""
    older: tuple[str, ...] | None = None
    """Where records written before ``where`` existed keep the figure."""

    def rate(self, results: Sequence[EpisodeResult]) -> Rate:
        return _rate([r for r in results if self.counts(r)])

    def read(self, record: Mapping[str, Any]) -> tuple[int, float | None]:
        """Episodes and success of this figure in a record: (0, None) where it has none."""
        for where in (self.where, self.older):
            node = None if where is None else entry(record, where)
            if node is not None and node.get(self.keys[0]):
                return int(node[self.keys[0]]), node.get(self.keys[1])
        return 0, None


def entry(record: Mapping[str, Any], where: tuple[str, ...]) -> Mapping[str, Any] | None:
    """The mapping that the keys ``where`` lead to in a record, or None where they lead to none."""
    node: Any = record
    for key in where:
        node = node.get(key) if isinstance(node, Mapping) else None
    return node if isinstance(node, Mapping) else None


def _kind_figures(kind: Kind) -> tuple[Figure, Figure]:
    """Episodes set up with ``kind``, and those of them in which a correction was spoken."""
    words = kind.value.replace("_", " ")
    return (
        Figure(f"success_{kind}", f"episodes_{kind}", words, lambda r: r.challenge == kind, ("by_kind", kind)),
        Figure(
            f"corrected_success_{kind}",
            f"corrected_episodes_{kind}",
            words,
            lambda r: r.challenge == kind and r.corrected,
            ("by_kind", kind, "corrected"),
            split=True,
        ),
    )


ORDINALS = {2: "second"}
"""The words for the corrections after the first, up to ``MAX_CORRECTIONS``."""


def after_correction(index: int) -> str:
    """The name of the figure on episodes in which at least ``index`` corrections were spoken."""
    return f"corrected_success_after_{index}"


def _index_figure(index: int) -> Figure:
    """Episodes in which at least ``index`` corrections were spoken: how the agent does once corrected again."""
    return Figure(
        after_correction(index),
        f"corrected_episodes_after_{index}",
        f"after a {ORDINALS[index]} correction",
        lambda r: r.corrections >= index,
        ("by_index", str(index)),
        split=True,
    )


def _form_figure(form: CorrectionForm) -> Figure:
    """Episodes whose spoken correction took ``form``; negations were kept under ``by_negation`` before."""
    article = "an" if form.value[0] in "aeiou" else "a"
    return Figure(
        f"corrected_success_{form}",
        f"corrected_episodes_{form}",
        f"after {article} {form}",
        lambda r: r.form is form,
        ("by_form", form),
        split=True,
        older=("by_negation", "with_negation") if form is CorrectionForm.NEGATION else None,
    )


FIGURES: Registry[Figure] = Registry("figure", lambda figure: figure.name)
"""The registry of the success rates every tool reports, in the order the tools show them."""

for _figure in (
    Figure("success", "episodes", "success", lambda r: True, ()),
    Figure(
        "correction_episode_success",
        "correction_episodes",
        "correction episodes",
        lambda r: r.challenge is not None,
        (),
        ("correction_episodes", "correction_episode_success"),
    ),
    Figure("corrected_success", "corrected_episodes", "corrected", lambda r: r.corrected, ("corrected",)),
    *(figure for kind in Kind for figure in _kind_figures(kind)),
    *(_form_figure(form) for form in CorrectionForm),
    *(_index_figure(index) for index in range(2, MAX_CORRECTIONS + 1)),
):
    FIGURES.register(_figure)

FIGURE = FIGURES.by_name
"""Each registered figure by its name."""

METRIC_NAMES: Live[str] = Live(
    lambda: (
        *(name for figure in FIGURES for name in (figure.count, figure.name)),
        *(f"{ATTENTION}_{phase}" for phase in PHASES),
    )
)
"""The flat metrics of one evaluation (``EvaluationReport.metrics``), as ``metrics.csv`` names its columns."""
