"""Learning curves from run folders: success against environment steps, like the paper's figures 3 and 4.

One panel for all episodes and one for the episodes in which a correction was spoken (``corrected_success``;
a run written before that metric existed shows its ``correction_success``, the success on correction
episodes, there instead). Runs come in groups (the seeds of one setting; one group unless the caller
groups them): each group is one line, the mean over its runs, with a band of the 95% bootstrap interval of
that mean (:mod:`lanrocli.core.stats`), each run's curve first interpolated onto the steps at which any run of
the group was evaluated; a run does not count beyond its last evaluation. Stage boundaries are dashed lines
at the median over a group's runs of the step where each stage began.
"""

from __future__ import annotations

import csv
import io
import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lanrocli.core.stats import bootstrap
from lanrocli.train.runfolder import METRICS

PANELS = (("success", "all episodes"), ("corrected_success", "episodes with a spoken correction"))
OLD_COLUMNS = {"corrected_success": "correction_success"}
"""Where ``metrics.csv`` files of older runs keep what a panel shows."""


@dataclass(frozen=True)
class Curve:
    """One run's evaluations."""

    name: str
    steps: np.ndarray
    values: dict[str, np.ndarray]
    """Column -> success per evaluation, NaN where that evaluation had no such episode."""
    boundaries: list[tuple[int, str]]
    """(environment steps, name of the stage that starts there) for every stage after the first."""


def read_run(run: Path) -> Curve:
    """The evaluations of the run folder ``run`` (or of a ``metrics.csv`` given directly)."""
    path = run / METRICS if run.is_dir() else run
    if not path.is_file():
        raise FileNotFoundError(f"{run} has no {METRICS}: is it a run folder written by 'lanro train'?")
    header, rows = _table(path)
    if not rows:
        raise ValueError(f"{path} has no evaluations yet")
    steps = np.array([_number(path, line, row, "env_steps", int) for line, row in rows])
    values = {}
    for column, _ in PANELS:
        source = column if column in header else OLD_COLUMNS.get(column, column)
        values[column] = np.array(
            [_number(path, line, row, source, float) if row.get(source) else np.nan for line, row in rows]
        )
    boundaries = [
        (int(steps[index]), row["stage_name"])
        for index, ((_, prev), (_, row)) in enumerate(zip(rows, rows[1:]))
        if row["stage"] != prev["stage"]
    ]
    return Curve(run.name if run.is_dir() else run.parent.name, steps, values, boundaries)


READ = ("stage", "stage_name", "env_steps", "success")
"""The columns a plot needs, which every ``metrics.csv`` has had: without them the header is lost."""


def _table(path: Path) -> tuple[list[str], list[tuple[int, dict[str, str]]]]:
    """The header of the CSV file at ``path`` and its rows, each with its line. A run killed while writing,
    or a hand edit, can damage the file; that is a ValueError at the line, never a KeyError from a plot."""
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        line = raw.count(b"\n", 0, error.start) + 1
        raise ValueError(f"{path}:{line}: not UTF-8 text ({error.reason}); the file is damaged") from None
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = next(reader, [])
        missing = [column for column in READ if column not in header]
        if header and missing:
            raise ValueError(
                f"{path}:1: the header has no column{'s' if len(missing) > 1 else ''} {', '.join(missing)}; the "
                f"first line of {METRICS} must name its columns, as 'lanro train' writes it"
            )
        rows = []
        for fields in reader:
            if not fields:
                continue  # a blank line
            if len(fields) != len(header):
                raise ValueError(
                    f"{path}:{reader.line_num}: {len(fields)} values where the header names {len(header)} columns; "
                    "the line is damaged: delete or repair it"
                )
            rows.append((reader.line_num, dict(zip(header, fields))))
    except csv.Error as error:
        raise ValueError(f"{path}:{reader.line_num}: not a CSV line ({error}); the file is damaged") from None
    return header, rows


def _number(path: Path, line: int, row: dict[str, str], column: str, kind: type[float] | type[int]) -> float:
    try:
        return kind(row[column])
    except ValueError:
        what = "a whole number" if kind is int else "a number"
        raise ValueError(f"{path}:{line}: {column} is {row[column]!r}, not {what}; the line is damaged") from None


BAND_RESAMPLES = 2000
"""Bootstrap resamples per plotted step: a band needs less precision than a reported interval."""


def mean_and_band(curves: Sequence[Curve], column: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Steps, the mean over the runs that reached each step, and the 95% bootstrap interval of that mean
    (NaN where no run had a value; the mean itself where one run had)."""
    grid = np.unique(np.concatenate([c.steps for c in curves]))
    stacked = np.full((len(curves), grid.size), np.nan)
    for i, curve in enumerate(curves):
        known = ~np.isnan(curve.values[column])
        if not known.any():
            continue
        xs, ys = curve.steps[known], curve.values[column][known]
        inside = (grid >= xs[0]) & (grid <= xs[-1])
        stacked[i, inside] = np.interp(grid[inside], xs, ys)
    mean, low, high = (np.full(grid.size, np.nan) for _ in range(3))
    for j in range(grid.size):
        values = stacked[~np.isnan(stacked[:, j]), j]
        if values.size == 1:
            mean[j] = low[j] = high[j] = values[0]
        elif values.size > 1:
            estimate = bootstrap(values, reps=BAND_RESAMPLES)
            mean[j], low[j], high[j] = estimate.value, estimate.low, estimate.high
    return grid, mean, low, high


def median_boundaries(curves: Sequence[Curve]) -> list[tuple[float, str]]:
    """Each stage boundary at the median over the runs that reached it."""
    most = max((len(c.boundaries) for c in curves), default=0)
    boundaries = []
    for k in range(most):
        reached = [c.boundaries[k] for c in curves if len(c.boundaries) > k]
        boundaries.append((float(np.median([step for step, _ in reached])), reached[0][1]))
    return boundaries


COLOURS = ("tab:red", "tab:blue", "tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive")


def plot_groups(groups: Sequence[tuple[str, Sequence[Path]]], out: Path, title: str | None = None) -> Path:
    """Draw one line per group of runs, labelled by the group's name, into ``out`` (PNG, SVG or PDF)."""
    import matplotlib

    matplotlib.use("Agg")  # files only: no display is needed, or wanted, on a cluster node
    import matplotlib.pyplot as plt

    read = [(label, [read_run(run) for run in runs]) for label, runs in groups]
    figure, axes = plt.subplots(1, len(PANELS), figsize=(11, 4), sharex=True, sharey=True)
    for axis, (column, panel) in zip(axes, PANELS):
        drawn = False
        for (label, curves), colour in zip(read, itertools.cycle(COLOURS)):
            steps, mean, low, high = mean_and_band(curves, column)
            known = ~np.isnan(mean)
            drawn |= bool(known.any())
            name = f"{label}: " if label else ""
            axis.plot(steps[known], mean[known], color=colour, label=f"{name}mean of {len(curves)} run(s)")
            if len(curves) > 1:
                axis.fill_between(steps[known], low[known], high[known], color=colour, alpha=0.2)
            line = colour if len(read) > 1 else "grey"
            for step, stage in median_boundaries(curves):
                axis.axvline(step, color=line, linestyle="--", linewidth=0.8)
                axis.text(
                    step,
                    0.97,
                    stage,
                    transform=axis.get_xaxis_transform(),
                    fontsize=7,
                    color=line,
                    rotation=90,
                    va="top",
                    ha="right",
                )
        if not drawn:
            axis.text(0.5, 0.5, "no such episodes evaluated", transform=axis.transAxes, ha="center", color="grey")
        axis.set_title(panel)
        axis.set_xlabel("environment steps")
        axis.set_ylim(-0.02, 1.02)
        axis.set_xlim(left=0)
        axis.grid(alpha=0.3)
    axes[0].set_ylabel("success rate")
    axes[0].legend(
        loc="lower right", title="band: 95% bootstrap interval" if any(len(c) > 1 for _, c in read) else None
    )
    runs = [curve for _, curves in read for curve in curves]
    figure.suptitle(title or ", ".join(c.name for c in runs))
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=120)
    plt.close(figure)
    return out
