"""``lanro report``: runs aggregated per task and stage, with bootstrap intervals over runs.

For every stage a run has ended, its run folder holds how many steps the stage took and whether its rule
promoted it (the run state in its latest checkpoint) and the test of the stage's agents on held-out episodes
(``test.json``). For each group of runs (the seeds of one setting, :mod:`lanrocli.report.groups`), each
task and each stage, every figure is given as the mean over runs with its 95% stratified bootstrap interval
(:mod:`lanrocli.core.stats`), and as the interquartile mean too where at least five runs have it. With several
groups the first is the reference: for each other group, the probability that one of its runs beats one of
the reference's (higher success, fewer steps), with its interval. The figures of one kind or form of
correction are marked where some run heard fewer than ``JUDGED`` of them: shown, not judged. The last
stage's correction test is aggregated like the test, its figures prefixed ``correction_test_``, and so are
the generalisation splits, each figure beside its drop from the in-distribution test.

A run that has not ended every stage counts for the stages it has ended. Reading needs neither torch nor
Ray, so a report is made in a moment on any machine that sees the folders. How it is laid out, as JSON or
Markdown, is :mod:`lanrocli.report.output`'s business.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from lanrocli.core.stats import IQM_RUNS, Estimate, bootstrap, iqm, probability_of_improvement
from lanrocli.evaluation.metrics import FIGURE, FIGURES, JUDGED, Figure
from lanrocli.evaluation.splits import SPLIT_FIGURES, SplitFigure, drop, in_distribution
from lanrocli.report.groups import Group, group_runs
from lanrocli.train.errors import CheckpointError
from lanrocli.train.report import run_ended
from lanrocli.train.runfolder import (
    CONFIG,
    CORRECTION_TEST,
    LATEST,
    SPLITS,
    STATE_FILE,
    TEST,
    read_pointer,
    stage_folder,
)

STEPS = "stage_steps"


@dataclass(frozen=True)
class Reported:
    """A test figure ``lanro report`` aggregates: its label, and how to read it from a stage's ``test.json``
    for one agent as (episodes, success); judged only from ``JUDGED`` episodes on where ``split``."""

    label: str
    read: Callable[[dict[str, Any], str], tuple[int, float | None]]
    split: bool


def _on_test(figure: Figure) -> Reported:
    return Reported(figure.label, lambda test, agent: figure.read(test.get(agent, {})), figure.split)


def _on_correction_test(figure: Figure) -> Reported:
    def read(test: dict[str, Any], agent: str) -> tuple[int, float | None]:
        return figure.read(test.get(CORRECTION_TEST, {}).get(agent, {}))

    return Reported(f"correction test: {figure.label}", read, figure.split)


def _on_split(figure: SplitFigure) -> Reported:
    def read(test: dict[str, Any], agent: str) -> tuple[int, float | None]:
        rate = figure.read(test[SPLITS][figure.split.value][agent]) if _has_split(test, figure, agent) else None
        return (rate["episodes"], rate["success"]) if rate else (0, None)

    return Reported(f"{figure.split.value} split: {figure.label}", read, False)


def _split_drop(figure: SplitFigure) -> Reported:
    """The points lost from the same agent's in-distribution figure, read as a rate so that it is shown in
    points like the figures beside it."""

    def read(test: dict[str, Any], agent: str) -> tuple[int, float | None]:
        if not _has_split(test, figure, agent):
            return 0, None
        record = test[SPLITS][figure.split.value][agent]
        mine = figure.read(record)
        points = drop(mine, in_distribution(figure, record, test[agent])[0])
        return (0, None) if points is None or mine is None else (mine["episodes"], points / 100)

    return Reported(f"{figure.split.value} split: drop of {figure.label} (points)", read, False)


def _has_split(test: dict[str, Any], figure: SplitFigure, agent: str) -> bool:
    return agent in test.get(SPLITS, {}).get(figure.split.value, {}) and agent in test


_SPOKEN = [figure for figure in FIGURES if figure.name.startswith("corrected_")]
"""The figures of episodes in which a correction was spoken: all of them, per kind and per form. The rates
of all episodes set up with a kind, which mix episodes with and without one, are not aggregated."""

METRICS: dict[str, Reported] = {
    **{name: _on_test(FIGURE[name]) for name in ("success", "correction_episode_success")},
    **{figure.name: _on_test(figure) for figure in _SPOKEN},
    **{f"{CORRECTION_TEST}_{figure.name}": _on_correction_test(figure) for figure in _SPOKEN},
    **{
        name: reported
        for figure in SPLIT_FIGURES
        for name, reported in (
            (f"{figure.split.value}_{figure.name}", _on_split(figure)),
            (f"{figure.split.value}_{figure.name}_drop", _split_drop(figure)),
        )
    },
}
"""The test figures reported, by their names in ``metrics.csv`` (those of the last stage's correction test
prefixed ``correction_test_``, those of the generalisation splits by the split's name, with their drops
from the in-distribution figure); a run without the figure (no such episode) does not count for it."""


class ReportError(ValueError):
    """Folders that cannot be reported on."""


@dataclass(frozen=True)
class StageOutcome:
    """One stage of one run, once ended."""

    task: str
    index: int
    name: str
    steps: int
    promoted: bool
    figures: dict[str, tuple[int, float | None]]
    """Metric -> (episodes, success) of the stage's agent."""


@dataclass(frozen=True)
class RunOutcome:
    path: Path
    ended: bool
    stages: list[StageOutcome]


def read_outcome(run: Path, agent: str = "last") -> RunOutcome:
    """What the run folder ``run`` says about its ended stages, with the figures of their ``agent``."""
    config = run / CONFIG
    try:
        plan = yaml.safe_load(config.read_text(encoding="utf-8"))
        task, names = str(plan["task"]), [str(stage["name"]) for stage in plan["stages"]]
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError) as error:
        raise ReportError(
            f"{run} is not a run folder with a readable {CONFIG} ({type(error).__name__}: {error})"
        ) from None
    try:
        state = json.loads((read_pointer(run / LATEST) / STATE_FILE).read_text())
        results = state["extra"]["run"]["results"]
    except FileNotFoundError:
        results = []
    except (CheckpointError, OSError, ValueError, KeyError, TypeError) as error:
        raise ReportError(f"{run}: the latest checkpoint's run state cannot be read ({error})") from None
    stages = []
    for result in results:
        index = int(result["index"])
        test = run / stage_folder(index, names[index]) / TEST
        record = json.loads(test.read_text()) if test.is_file() else {}
        figures = {name: reported.read(record, agent) for name, reported in METRICS.items()}
        steps = int(result["end"]) - int(result["start"])
        stages.append(StageOutcome(task, index, names[index], steps, result["ended"] == "promoted", figures))
    return RunOutcome(run, run_ended(run), stages)


@dataclass
class Cell:
    """One figure of one group at one stage: its estimate over the runs that have it."""

    values: list[float]
    mean: Estimate
    iqm: Estimate | None
    fewest: int | None = None
    """The fewest episodes behind one run's value (None for steps)."""
    judged: bool = True
    """False for a kind or form some run heard fewer than ``JUDGED`` spoken corrections of."""

    def to_dict(self) -> dict[str, Any]:
        data: dict[str, Any] = {
            "mean": self.mean.value,
            "ci": list(self.mean.ci),
            "runs": self.mean.runs,
            "values": self.values,
        }
        if self.iqm is not None:
            data |= {"iqm": self.iqm.value, "iqm_ci": list(self.iqm.ci)}
        if self.fewest is not None:
            data |= {"fewest_episodes": self.fewest, "judged": self.judged}
        return data


def _cell(values: list[float], episodes: list[int] | None = None, split: bool = False) -> Cell | None:
    if not values:
        return None
    fewest = min(episodes) if episodes else None
    judged = not split or fewest is None or fewest >= JUDGED
    return Cell(values, bootstrap(values), bootstrap(values, iqm) if len(values) >= IQM_RUNS else None, fewest, judged)


StageKey = tuple[str, int, str]
"""(task, stage index, stage name)"""


@dataclass
class GroupReport:
    group: Group
    outcomes: list[RunOutcome]
    cells: dict[StageKey, dict[str, Cell]] = field(default_factory=dict)
    promoted: dict[StageKey, int] = field(default_factory=dict)


@dataclass
class Report:
    agent: str
    groups: list[GroupReport]
    comparisons: dict[tuple[StageKey, str, int], Estimate]
    """(stage, metric, group index) -> P(that group beats the first)."""

    @property
    def stages(self) -> list[StageKey]:
        keys = {key for group in self.groups for key in group.cells}
        return sorted(keys, key=lambda k: (k[0], k[1], k[2]))


def _higher_is_better(values: list[float], metric: str) -> np.ndarray:
    return -np.asarray(values, float) if metric == STEPS else np.asarray(values, float)


def make_report(paths: list[Path], agent: str = "last") -> Report:
    """The report on the runs and sweep folders ``paths``."""
    try:
        groups = group_runs(paths)
    except ValueError as error:
        raise ReportError(str(error)) from None
    reports = []
    for group in groups:
        outcomes = [read_outcome(run, agent) for run in group.runs]
        report = GroupReport(group, outcomes)
        collected: dict[StageKey, dict[str, list[float]]] = {}
        counts: dict[StageKey, dict[str, list[int]]] = {}
        for outcome in outcomes:
            for stage in outcome.stages:
                key = (stage.task, stage.index, stage.name)
                values, episodes = collected.setdefault(key, {}), counts.setdefault(key, {})
                values.setdefault(STEPS, []).append(float(stage.steps))
                report.promoted[key] = report.promoted.get(key, 0) + stage.promoted
                for name, (n, value) in stage.figures.items():
                    if value is not None:
                        values.setdefault(name, []).append(float(value))
                        episodes.setdefault(name, []).append(n)
        for key, values in collected.items():
            report.cells[key] = {
                name: cell
                for name, v in values.items()
                if (cell := _cell(v, counts[key].get(name), name in METRICS and METRICS[name].split)) is not None
            }
        reports.append(report)
    comparisons = {}
    if reports:
        reference = reports[0]
        for number, other in enumerate(reports[1:], start=1):
            for key, cells in other.cells.items():
                for metric, cell in cells.items():
                    base = reference.cells.get(key, {}).get(metric)
                    if base is not None:
                        comparisons[(key, metric, number)] = probability_of_improvement(
                            _higher_is_better(cell.values, metric), _higher_is_better(base.values, metric)
                        )
    return Report(agent, reports, comparisons)
