"""The generalisation splits in a run's records: which figure judges each split, and its drop from the same
agent's in-distribution figure, for ``report.md``, ``lanro eval --split`` and ``lanro report``.

A split that changes only what is said (a correction's words, the paraphrase split's verbs and corrections)
or when a correction comes is measured twice on the same seeds: on its held-out episodes and on its control,
the same scenes and goals with nothing held out.
Its drop is taken from the control, so it is the held-out part's alone. Against the ordinary test it would
also carry the difference between two samples of episodes, the test's few spoken corrections and the
split's, which alone moves a drop by several points from seed to seed."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from lanrocli.core.choices import Kind, Split
from lanrocli.core.stats import paired_rate_difference
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation.metrics import FIGURE, EpisodeResult, entry
from lanrocli.evaluation.quota import correction_changes


@dataclass(frozen=True)
class SplitFigure:
    """One figure of a split's record set against the same figure of the in-distribution test."""

    split: Split
    name: str
    """The key of its drop in a split record."""
    label: str
    figure: str
    """The name in ``FIGURES`` of the rate it reads: which episodes it counts and where a record keeps it."""

    def read(self, record: dict[str, Any]) -> dict[str, Any] | None:
        """The figure's rate (``episodes``, ``success``, ``ci``) in a test record, or None if it has none."""
        where = FIGURE[self.figure].where
        if not where:  # the record's own rate, whose interval sits beside it
            return {"episodes": record["episodes"], "success": record["success"], "ci": record["success_ci"]}
        node = entry(record, where)
        return None if node is None else dict(node)


CONTROLLED: frozenset[Split] = frozenset({Split.CORRECTION_WORDS, Split.LATE_CORRECTIONS, Split.PARAPHRASE})
"""The splits measured against a control. The pairs split changes the goal, so no episode of it can be
played with nothing held out: the ordinary test, built like it, is its in-distribution figure. Common
ground is judged on its own figure."""

CONTROL = "control"
"""The key of a split record's control: the record of the same episodes with nothing held out."""

DROP = "drop"
"""The key of a split record's drops from its control, by figure: points and their paired interval."""


SPLIT_FIGURES: tuple[SplitFigure, ...] = (
    SplitFigure(Split.PAIRS, "success", "success", "success"),
    SplitFigure(Split.PAIRS, "corrected", "corrected", "corrected_success"),
    SplitFigure(Split.CORRECTION_WORDS, "corrected", "corrected", "corrected_success"),
    SplitFigure(Split.LATE_CORRECTIONS, "corrected", "corrected", "corrected_success"),
    SplitFigure(Split.COMMON_GROUND, "common_ground", "corrected, common ground", "corrected_success_common_ground"),
    SplitFigure(Split.PARAPHRASE, "success", "success", "success"),
    SplitFigure(Split.PARAPHRASE, "corrected", "corrected", "corrected_success"),
)
"""What each split is judged on: the pairs split changes the goal of every episode, so success and the
corrected success; the paraphrase split rewords some instructions too, so both as well; the others change
what a correction episode says or when, so the corrected success."""


def in_distribution(
    figure: SplitFigure, split_record: dict[str, Any], test: dict[str, Any] | None
) -> tuple[dict[str, Any] | None, str]:
    """The figure the split is set against, and what it is: the split's control where it was measured,
    else the agent's ordinary test record ``test`` (runs tested before controls existed)."""
    if CONTROL in split_record:
        return figure.read(split_record[CONTROL]), "control"
    return (figure.read(test) if test is not None else None), "test"


def split_changes(split: Split) -> Callable[[EnvSettings], dict[str, Any]]:
    """A split's changes to the last stage: the pairs split keeps the stage as it is (its goal alone
    differs); the others make every episode a correction episode, of the common-ground kind for that split,
    so that the thing held out is heard in every episode where the agent errs (the paraphrase split's
    negations as often as the correction test's, and one correction an episode, so that every phrasing
    fits the sentence)."""

    def changes(stage: EnvSettings) -> dict[str, Any]:
        if split is Split.PAIRS:
            return {}
        if split is Split.COMMON_GROUND:
            return {"correction_rate": 1.0, "kinds": (Kind.COMMON_GROUND,)}
        if split is Split.PARAPHRASE:  # one correction: a long phrasing leaves no room for a second
            return {**correction_changes(stage), "max_corrections": 1}
        return {"correction_rate": 1.0}

    return changes


def paired_drops(split: Split, held: list[EpisodeResult], control: list[EpisodeResult]) -> dict[str, Any]:
    """Each figure of ``split``: points lost from the control to the held-out episodes, episode ``i`` of each
    played from the same seed, with a bootstrap interval that draws episodes, not ways of playing them (so
    the scenes and mistakes the two share do not widen it). None where either counts no episode."""
    if len(held) != len(control):
        raise ValueError(f"a paired drop needs the same episodes both ways, not {len(held)} and {len(control)}")
    drops: dict[str, Any] = {}
    for figure in SPLIT_FIGURES:
        if figure.split is split:
            counts = FIGURE[figure.figure].counts
            counted = np.array([[counts(r) for r in results] for results in (control, held)])
            won = np.array([[r.success for r in results] for results in (control, held)])
            if not counted.any(axis=1).all():
                drops[figure.name] = None
                continue
            estimate = paired_rate_difference(counted, won)
            drops[figure.name] = {"points": 100 * estimate.value, "ci": [100 * estimate.low, 100 * estimate.high]}
    return drops


def drop(split_rate: dict[str, Any] | None, in_distribution: dict[str, Any] | None) -> float | None:
    """Points lost from the in-distribution figure to the split's (positive: worse on the split)."""
    if not split_rate or not in_distribution or not split_rate["episodes"] or not in_distribution["episodes"]:
        return None
    return 100 * (in_distribution["success"] - split_rate["success"])


def split_lines(splits: dict[str, dict[str, dict[str, Any]]], ordinary: dict[str, dict[str, Any]]) -> list[str]:
    """The section of ``report.md`` on the splits: ``splits`` by split and agent, ``ordinary`` the same
    agents' in-distribution test records."""
    lines = [
        "",
        "## Generalisation splits: the final stage's agents on what training never showed",
        "",
        "Each split's held-out episodes (docs/generalisation.md) against the same agent's in-distribution "
        "figure: for the correction words, late corrections and paraphrases the control (the split's own seeds "
        "with nothing held out), for the pairs the test above. Drop in points, positive where the split is "
        "harder, with its 95% paired bootstrap interval where there is a control. Success with 95% Wilson "
        "interval (episodes).",
        "",
        "| split | agent | figure | split's episodes | in distribution | from | drop |",
        "|---|---|---|---|---|---|---|",
    ]
    for figure in SPLIT_FIGURES:
        for agent, record in splits.get(figure.split.value, {}).items():
            mine = figure.read(record)
            theirs, source = in_distribution(figure, record, ordinary.get(agent))
            lines.append(
                f"| {figure.split.value} | {agent} | {figure.label} | {with_interval(mine)} | "
                f"{with_interval(theirs)} | "
                f"{source if theirs else '-'} | {_points(figure, record, mine, theirs)} |"
            )
    return lines


def control_lines(split: Split, record: dict[str, Any]) -> list[str]:
    """What ``lanro eval --split`` says under its table: each figure of the split against its control, and
    the corrected success of each phrasing where the split paraphrases."""
    lines = []
    for figure in SPLIT_FIGURES:
        if figure.split is split and CONTROL in record:
            mine, theirs = figure.read(record), figure.read(record[CONTROL])
            lines.append(
                f"{figure.label}: {with_interval(mine)} here, {with_interval(theirs)} on the control (the same "
                f"episodes with nothing held out): drop {_points(figure, record, mine, theirs)} points"
            )
    for name, rate in record.get("by_phrasing", {}).items():
        lines.append(f"corrected, spoken as {name!r}: {with_interval(rate)}")
    return lines


def _points(
    figure: SplitFigure, record: dict[str, Any], mine: dict[str, Any] | None, theirs: dict[str, Any] | None
) -> str:
    """A drop as ``+2.7 [-1.9, 7.4]`` where the record holds its paired interval, else as ``+2.7``."""
    paired = record.get(DROP, {}).get(figure.name)
    if paired is not None:
        low, high = paired["ci"]
        return f"{paired['points']:+.1f} [{low:+.1f}, {high:+.1f}]"
    points = drop(mine, theirs)
    return "-" if points is None else f"{points:+.1f}"


def with_interval(rate: dict[str, Any] | None) -> str:
    """A rate of a ``test.json`` record as ``92.0% [89.3, 94.1] (n)``, or ``-`` without episodes."""
    if not rate or not rate["episodes"]:
        return "-"
    low, high = rate["ci"]
    return f"{100 * rate['success']:.1f}% [{100 * low:.1f}, {100 * high:.1f}] ({rate['episodes']})"
