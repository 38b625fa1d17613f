"""The generalisation splits in a run's records: which figure judges each split, and its drop from the same
agent's in-distribution test, for ``report.md``, ``lanro eval --split`` and ``lanro report``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from lanrocli.choices import Kind, Split


@dataclass(frozen=True)
class SplitFigure:
    """One figure of a split's record set against the same figure of the in-distribution test."""

    split: Split
    name: str
    label: str

    def read(self, record: dict[str, Any]) -> dict[str, Any] | None:
        """The figure's rate (``episodes``, ``success``, ``ci``) in a test record, or None if it has none."""
        if self.name == "success":
            return {"episodes": record["episodes"], "success": record["success"], "ci": record["success_ci"]}
        if self.name == "common_ground":
            return record["by_kind"].get(Kind.COMMON_GROUND.value, {}).get("corrected")
        return record[self.name]


SPLIT_FIGURES: tuple[SplitFigure, ...] = (
    SplitFigure(Split.PAIRS, "success", "success"),
    SplitFigure(Split.PAIRS, "corrected", "corrected"),
    SplitFigure(Split.CORRECTION_WORDS, "corrected", "corrected"),
    SplitFigure(Split.LATE_CORRECTIONS, "corrected", "corrected"),
    SplitFigure(Split.COMMON_GROUND, "common_ground", "corrected, common ground"),
)
"""What each split is judged on: the pairs split changes the goal of every episode, so success and the
corrected success; the others change what a correction episode says or when, so the corrected success."""


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
        "Each split's held-out episodes (docs/generalisation.md) against the same agent's test above; drop in "
        "points, positive where the split is harder. Success with 95% Wilson interval (episodes).",
        "",
        "| split | agent | figure | split's episodes | in distribution | drop |",
        "|---|---|---|---|---|---|",
    ]
    for figure in SPLIT_FIGURES:
        for agent, record in splits.get(figure.split.value, {}).items():
            mine, theirs = figure.read(record), figure.read(ordinary[agent]) if agent in ordinary else None
            points = drop(mine, theirs)
            lines.append(
                f"| {figure.split.value} | {agent} | {figure.label} | {with_interval(mine)} | {with_interval(theirs)} | "
                f"{'-' if points is None else f'{points:+.1f}'} |"
            )
    return lines


def with_interval(rate: dict[str, Any] | None) -> str:
    """A rate of a ``test.json`` record as ``92.0% [89.3, 94.1] (n)``, or ``-`` without episodes."""
    if not rate or not rate["episodes"]:
        return "-"
    low, high = rate["ci"]
    return f"{100 * rate['success']:.1f}% [{100 * low:.1f}, {100 * high:.1f}] ({rate['episodes']})"
