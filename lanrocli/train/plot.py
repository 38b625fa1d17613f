"""Learning curves from run folders: success against environment steps, like the paper's figures 3 and 4.

One panel for all episodes and one for the episodes in which a correction was spoken (``corrected_success``;
a run written before that metric existed shows its ``correction_success``, the success on correction
episodes, there instead). Several runs (seeds) are drawn as their mean
with a band of one standard deviation, each run's curve first interpolated onto the steps at which any of
them was evaluated; a run does not count beyond its last evaluation. Stage boundaries are dashed lines.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

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


def mean_and_spread(curves: Sequence[Curve], column: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Steps, mean and standard deviation over the runs that reached each step (NaN where none had a value)."""
    grid = np.unique(np.concatenate([c.steps for c in curves]))
    stacked = np.full((len(curves), grid.size), np.nan)
    for i, curve in enumerate(curves):
        known = ~np.isnan(curve.values[column])
        if not known.any():
            continue
        xs, ys = curve.steps[known], curve.values[column][known]
        inside = (grid >= xs[0]) & (grid <= xs[-1])
        stacked[i, inside] = np.interp(grid[inside], xs, ys)
    counts = (~np.isnan(stacked)).sum(axis=0)
    with np.errstate(invalid="ignore"):
        mean = np.where(counts > 0, np.nansum(stacked, axis=0) / np.maximum(counts, 1), np.nan)
        spread = np.sqrt(np.where(counts > 0, np.nansum((stacked - mean) ** 2, axis=0) / np.maximum(counts, 1), np.nan))
    return grid, mean, spread


def plot_runs(runs: Sequence[Path], out: Path, title: str | None = None) -> Path:
    """Draw the runs' curves into ``out`` (PNG, SVG or PDF, by its suffix)."""
    import matplotlib

    matplotlib.use("Agg")  # files only: no display is needed, or wanted, on a cluster node
    import matplotlib.pyplot as plt

    curves = [read_run(run) for run in runs]
    figure, axes = plt.subplots(1, len(PANELS), figsize=(11, 4), sharex=True, sharey=True)
    for axis, (column, label) in zip(axes, PANELS):
        steps, mean, spread = mean_and_spread(curves, column)
        known = ~np.isnan(mean)
        axis.plot(steps[known], mean[known], color="tab:red", label=f"mean of {len(curves)} run(s)")
        if len(curves) > 1:
            axis.fill_between(
                steps[known], (mean - spread)[known], (mean + spread)[known], color="tab:red", alpha=0.2, label="± 1 sd"
            )
        for curve in curves:
            for step, name in curve.boundaries:
                axis.axvline(step, color="grey", linestyle="--", linewidth=0.8)
                axis.text(
                    step, 0.97, name, transform=axis.get_xaxis_transform(), fontsize=7, color="grey", rotation=90,
                    va="top", ha="right",
                )
        if not known.any():
            axis.text(0.5, 0.5, "no such episodes evaluated", transform=axis.transAxes, ha="center", color="grey")
        axis.set_title(label)
        axis.set_xlabel("environment steps")
        axis.set_ylim(-0.02, 1.02)
        axis.set_xlim(left=0)
        axis.grid(alpha=0.3)
    axes[0].set_ylabel("success rate")
    axes[0].legend(loc="lower right")
    figure.suptitle(title or ", ".join(c.name for c in curves))
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=120)
    plt.close(figure)
    return out
