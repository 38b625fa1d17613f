"""The ``lanro report`` as JSON and as Markdown: the aggregated figures of :mod:`lanrocli.report.aggregate` laid out
per group, task and stage. Like it, this loads neither torch nor Ray."""

from __future__ import annotations

from typing import Any

from lanrocli.core.stats import CONFIDENCE, IQM_RUNS, REPS, Estimate
from lanrocli.evaluation.metrics import JUDGED
from lanrocli.report.aggregate import METRICS, STEPS, GroupReport, Report, StageKey


def _label(group: GroupReport) -> str:
    return group.group.label or "all runs"


def to_json(report: Report) -> dict[str, Any]:
    """Per group, stage and metric: ``mean``, ``ci``, ``runs`` (and ``iqm``, ``iqm_ci`` from five runs on)."""
    groups = []
    for number, group in enumerate(report.groups):
        stages = []
        for key in report.stages:
            if key not in group.cells:
                continue
            metrics = {name: cell.to_dict() for name, cell in group.cells[key].items()}
            if STEPS in metrics:
                metrics[STEPS]["promoted"] = group.promoted.get(key, 0)
            for (other_key, metric, other), estimate in report.comparisons.items():
                if other_key == key and other == number and metric in metrics:
                    metrics[metric]["beats_first"] = {"probability": estimate.value, "ci": list(estimate.ci)}
            stages.append({"task": key[0], "stage": key[1] + 1, "name": key[2], "metrics": metrics})
        groups.append(
            {
                "label": _label(group),
                "settings": group.group.settings,
                "runs": [str(outcome.path) for outcome in group.outcomes],
                "ended": sum(outcome.ended for outcome in group.outcomes),
                "stages": stages,
            }
        )
    return {"agent": report.agent, "confidence": CONFIDENCE, "resamples": REPS, "groups": groups}


def _number(metric: str, value: float) -> str:
    return f"{value:,.0f}" if metric == STEPS else f"{100 * value:.1f}"


def _estimate(metric: str, estimate: Estimate) -> str:
    return f"{_number(metric, estimate.value)} [{_number(metric, estimate.low)}, {_number(metric, estimate.high)}]"


def _row(report: Report, key: StageKey, metric: str, label: str, use_iqm: bool) -> list[str] | None:
    """A table row of ``metric`` at stage ``key``, or None where no group has the figure."""
    cells = [f"{label}, IQM" if use_iqm else label]
    found = False
    for number, group in enumerate(report.groups):
        cell = group.cells.get(key, {}).get(metric)
        estimate = None if cell is None else cell.iqm if use_iqm else cell.mean
        text = "-"
        if estimate is not None:
            found = True
            text = _estimate(metric, estimate)
            if estimate.runs < len(group.outcomes):
                text += f" ({estimate.runs})"
            if metric == STEPS and not use_iqm:
                text += f", {group.promoted.get(key, 0)} promoted"
            if cell is not None and not cell.judged:
                text += "*"
        cells.append(text)
        if number:
            comparison = None if use_iqm else report.comparisons.get((key, metric, number))
            cells.append(
                "" if comparison is None else f"{comparison.value:.2f} [{comparison.low:.2f}, {comparison.high:.2f}]"
            )
    return cells if found else None


def to_markdown(report: Report) -> str:
    """The report as Markdown: one table per task and stage, one column per group."""
    runs = sum(len(group.outcomes) for group in report.groups)
    lines = [
        f"# Report: {runs} run{'s' * (runs != 1)}",
        "",
        f"Per task and stage: the steps the stage took, and its `{report.agent}` agent on the stage's held-out test "
        f"episodes (success in %). Mean over runs with a {CONFIDENCE:.0%} stratified bootstrap interval "
        f"({REPS:,} resamples), and the interquartile mean (IQM) where at least {IQM_RUNS} runs have the figure; "
        "(n): the runs that have it, where fewer than the group's.",
        "",
    ]
    for group in report.groups:
        ended = sum(outcome.ended for outcome in group.outcomes)
        names = ", ".join(outcome.path.name for outcome in group.outcomes)
        lines.append(f"- {_label(group)}: {len(group.outcomes)} runs ({names}), {ended} ended")
    reference = _label(report.groups[0]) if report.groups else ""
    if len(report.groups) > 1:
        lines += [
            "",
            f"P(beats {reference}): the probability that a run of the group to its left beats one of {reference} "
            "(higher success, fewer steps), with its interval.",
        ]
    labels = {STEPS: "steps in stage"} | {metric: reported.label for metric, reported in METRICS.items()}
    for key in report.stages:
        header = ["figure"]
        for number, group in enumerate(report.groups):
            header += [f"{_label(group)} ({len(group.outcomes)} runs)"] + ([f"P(beats {reference})"] if number else [])
        lines += ["", f"## {key[0]}: stage {key[1] + 1}, {key[2]}", "", "| " + " | ".join(header) + " |"]
        lines.append("|" + "---|" * len(header))
        with_iqm = any(cell.iqm is not None for group in report.groups for cell in group.cells.get(key, {}).values())
        for metric, label in labels.items():
            for use_iqm in (False, True) if with_iqm else (False,):
                row = _row(report, key, metric, label, use_iqm)
                if row is not None:
                    lines.append("| " + " | ".join(row) + " |")
    if any(not cell.judged for group in report.groups for cells in group.cells.values() for cell in cells.values()):
        lines += [
            "",
            f"\\* Some run heard fewer than {JUDGED} spoken corrections of this kind or form: shown, not judged.",
        ]
    return "\n".join(lines) + "\n"
