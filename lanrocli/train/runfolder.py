"""The run folder: the names of everything in it, the pointers that name its checkpoints, and ``metrics.csv``.

The run folder holds everything a researcher looks at or resumes from::

    config.yaml                  the resolved curriculum; --resume refuses a curriculum that differs
    metrics.csv                  one row per evaluation
    report.md                    the per-stage table, rewritten whenever a stage ends
    latest                       pointer to the newest checkpoint
    stage-K-NAME/step-N/         the stage's two newest resumable checkpoints (agent, buffer, environments)
    stage-K-NAME/best-N/         the agent of the stage's best evaluation (agent and state only)
    stage-K-NAME/last, best      pointers to the newest step-N and to best-N
    stage-K-NAME/test.json       the stage's last and best agents on its held-out test episodes
                                 (the last stage's also on the correction test)
    events.*                     TensorBoard events, when the tensorboard package is installed
                                 (:mod:`lanrocli.train.tensorboard`)
    .lock                        locked by the process that writes the run (names it)
    set-aside/                   checkpoints newer than the one a run resumed from after damage

How each file is written whole, and the lock on the folder, are :mod:`lanrocli.train.writing`'s business;
``report.md`` is :mod:`lanrocli.train.report`'s; what a damaged or killed run left is
:mod:`lanrocli.train.recovery`'s. The stage keeps the checkpoint before its newest, so a damaged newest one
costs one evaluation's steps, not the stage.

This module loads neither torch nor pybullet, so plotting and reading a run folder stay quick.
"""

from __future__ import annotations

import contextlib
import csv
import os
import re
import shutil
from pathlib import Path
from typing import Any

from lanrocli.agent.settings import UPDATE_METRICS
from lanrocli.core.registry import Live
from lanrocli.evaluation.metrics import METRIC_NAMES
from lanrocli.train.errors import CheckpointError
from lanrocli.train.writing import fsync_dir, fsync_file, temporary

CONFIG = "config.yaml"
METRICS = "metrics.csv"
REPORT = "report.md"
TEST = "test.json"
BEST = "best"
LAST = "last"
LATEST = "latest"
LANGUAGE = "language"
"""Key of ``test.json`` under which the last stage's final agent is measured with each ``Instruction``."""
CORRECTION_TEST = "correction_test"
"""Key of ``test.json`` under which the last stage's agents are measured by the correction test."""
QUESTION_TEST = "question_test"
"""Key of ``test.json`` under which the last stage's agents are measured asking questions, and without."""
SPLITS = "splits"
"""The key of ``test.json`` holding the generalisation splits' records, by split and agent."""
SET_ASIDE = "set-aside"
STATE_FILE = "state.json"
"""The file of a checkpoint that holds the run's position in its curriculum beside the trainer's state."""
STAGE_FOLDER = re.compile(r"stage-\d+-.+")
STEP_CHECKPOINT = re.compile(r"step-(\d+)")
BEST_CHECKPOINT = re.compile(r"best-(\d+)")

METRIC_COLUMNS: Live[str] = Live(
    lambda: (
        "stage",
        "stage_name",
        "env_steps",
        "stage_steps",
        "wall_time",
        *METRIC_NAMES,
        "mean_return",
        "mean_length",
        "train_success",
        "rule_value",
        "rule_holds",
        *UPDATE_METRICS,
    )
)
"""The columns this version writes: read from the figures registered when a row is written."""


# -- names -------------------------------------------------------------------------------------------------


def stage_folder(index: int, name: str) -> str:
    """The folder of the stage at ``index`` named ``name``: ``stage-2-corrections``."""
    return f"stage-{index + 1}-{name}"


def step_checkpoint(env_steps: int) -> str:
    """Zero-padded, so that the checkpoints of a stage sort by their steps."""
    return f"step-{env_steps:010d}"


def best_checkpoint(env_steps: int) -> str:
    return f"best-{env_steps:010d}"


# -- pointers ----------------------------------------------------------------------------------------------


def write_pointer(pointer: Path, target: str) -> None:
    """Point ``pointer`` (a small text file) at ``target`` atomically."""
    tmp = temporary(pointer)
    tmp.write_text(target + "\n")
    fsync_file(tmp)
    os.replace(tmp, pointer)
    fsync_dir(pointer.parent)


def read_pointer(pointer: Path) -> Path:
    if not pointer.is_file():
        raise CheckpointError(f"no checkpoint pointer at {pointer}")
    try:
        target = pointer.read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError) as error:
        raise CheckpointError(f"the pointer {pointer} is damaged: {error}") from None
    if not target or "\n" in target or "\0" in target:
        raise CheckpointError(f"the pointer {pointer} is damaged: it names no checkpoint")
    return pointer.parent / target


def prune(directory: Path, keep: set[Path]) -> None:
    """Remove checkpoint directories under ``directory`` except ``keep``, and stale temporary ones."""
    kept = {k.resolve() for k in keep}
    for child in directory.iterdir():
        if child.is_dir() and child.resolve() not in kept:
            shutil.rmtree(child, ignore_errors=True)


def publish(out: Path, last: Path, best: Path | None) -> None:
    """Point the stage folder's ``last`` (and ``best``, when given) and the run's ``latest`` at checkpoints
    just written, then remove the stage's checkpoints that no pointer names, but for the one ``last`` named
    before. Pointers change only once their checkpoints are whole and pruning comes after them, so a kill
    at any moment leaves one to resume from."""
    folder = last.parent
    previous = _pointed(folder, LAST)
    if best is not None:
        write_pointer(folder / BEST, best.name)
    write_pointer(folder / LAST, last.name)
    write_pointer(out / LATEST, f"{folder.name}/{last.name}")
    prune(folder, {last, *previous, *_pointed(folder, BEST)})


def _pointed(folder: Path, *names: str) -> list[Path]:
    """What the pointers ``names`` of ``folder`` name now (a damaged pointer names nothing)."""
    targets = []
    for name in names:
        with contextlib.suppress(CheckpointError):
            targets.append(read_pointer(folder / name))
    return targets


# -- what a run folder holds -------------------------------------------------------------------------------


def checkpoint_steps(directory: Path) -> int | None:
    """The environment steps in a checkpoint's name, or None for a name that is not one."""
    match = STEP_CHECKPOINT.fullmatch(directory.name) or BEST_CHECKPOINT.fullmatch(directory.name)
    return int(match.group(1)) if match else None


# -- metrics.csv -------------------------------------------------------------------------------------------


def metric_columns(header: list[str]) -> list[str]:
    """The columns of a ``metrics.csv`` whose header is ``header``: this version's, then those that only an
    older version wrote (kept, so no figure of an older run is lost)."""
    current = tuple(METRIC_COLUMNS)
    return [*current, *(column for column in header if column not in current)]


def _header(path: Path) -> list[str]:
    with open(path, newline="") as f:
        return next(csv.reader(f), [])


def _read_metrics(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def _write_metrics(path: Path, columns: list[str], rows: list[dict[str, Any]]) -> None:
    """Replace ``path`` whole; a value missing from a row is left empty, as a figure without episodes is."""
    tmp = temporary(path)
    with open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, restval="")
        writer.writeheader()
        writer.writerows(rows)
    tmp.replace(path)


def align_metrics(path: Path) -> list[str]:
    """Give an existing ``metrics.csv`` this version's columns, returning those it gained (empty in its
    older rows). A run written by an older version and resumed by this one would otherwise append rows
    longer than their header, which no reader can parse."""
    if not path.is_file() or path.stat().st_size == 0:
        return []
    header = _header(path)
    columns = metric_columns(header)
    if header == columns:
        return []
    _write_metrics(path, columns, _read_metrics(path)[1])
    return [column for column in columns if column not in header]


def append_metrics(path: Path, row: dict[str, Any]) -> None:
    """Append an evaluation's row, first giving a file of an older version this version's columns."""
    align_metrics(path)
    new = not path.is_file() or path.stat().st_size == 0
    header = list(METRIC_COLUMNS) if new else _header(path)
    with open(path, "a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=header, restval="")
        if new:
            writer.writeheader()
        writer.writerow(row)


def truncate_metrics(path: Path, env_steps: int) -> None:
    """Drop rows written after the checkpoint a run resumes from: the resumed run writes them again."""
    if not path.is_file():
        return
    header, rows = _read_metrics(path)
    kept = [r for r in rows if int(r["env_steps"]) <= env_steps]
    if len(kept) < len(rows):
        _write_metrics(path, header, kept)
