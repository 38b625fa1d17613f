"""The run folder: the names of everything in it, how each file is written, and ``report.md``.

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

Whatever may be read while a run is killed is replaced whole: it is written under a temporary name
(``TMP_PREFIX``), then renamed into place. A pointer changes only after the checkpoint it names is complete
on disk, so a kill at any moment leaves the previous checkpoint and the pointer to it whole. The stage keeps
the checkpoint before its newest, so a damaged newest one costs one evaluation's steps, not the stage.

One process writes a run folder at a time: it holds an OS lock on ``.lock``, which the kernel releases when
the process ends however it ends, so a killed run never leaves a stale lock. Readers (``lanro eval``,
``lanro plot``) do not take it.

This module loads neither torch nor pybullet, so plotting and reading a run folder stay quick.
"""

from __future__ import annotations

import csv
import fcntl
import json
import math
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lanrocli.choices import Kind
from lanrocli.envs.figures import ATTENTION, FIGURES, JUDGED, METRIC_NAMES, PHASES
from lanrocli.train.generalisation import split_lines, with_interval

if TYPE_CHECKING:
    from lanrocli.train.curriculum import Curriculum
    from lanrocli.train.pipeline import RunState

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
SPLITS = "splits"
"""The key of ``test.json`` holding the generalisation splits' records, by split and agent."""
"""Key of ``test.json`` under which the last stage's agents are measured by the correction test."""
TMP_PREFIX = ".tmp-"
LOCK = ".lock"
SET_ASIDE = "set-aside"
STATE_FILE = "state.json"
"""The file of a checkpoint that holds the run's position in its curriculum beside the trainer's state."""
STATUS = "Status: "
"""How the line of ``report.md`` that says whether the run has ended begins."""
FINISHED = "finished"
STOPPED_BY_BUDGET = "stopped: a budget ran out with on_budget: stop"
_STAGE_FOLDER = re.compile(r"stage-\d+-.+")
_STEP_CHECKPOINT = re.compile(r"step-(\d+)")
_BEST_CHECKPOINT = re.compile(r"best-(\d+)")

AGENT_METRICS = (
    "critic_loss", "actor_loss", "alpha_loss", "grounding_loss", "alpha", "q_mean", "target_q_mean", "entropy"
)
METRIC_COLUMNS = (
    "stage", "stage_name", "env_steps", "stage_steps", "wall_time", *METRIC_NAMES, "mean_return", "mean_length",
    "train_success", "rule_value", "rule_holds", *AGENT_METRICS,
)


class CheckpointError(RuntimeError):
    """A checkpoint is missing, incomplete, damaged, or not plain data."""


class RunError(RuntimeError):
    """A run cannot start or resume as asked (the folder is in use, the curriculum changed, ...)."""


# -- names -------------------------------------------------------------------------------------------------


def stage_folder(index: int, name: str) -> str:
    """The folder of the stage at ``index`` named ``name``: ``stage-2-corrections``."""
    return f"stage-{index + 1}-{name}"


def step_checkpoint(env_steps: int) -> str:
    """Zero-padded, so that the checkpoints of a stage sort by their steps."""
    return f"step-{env_steps:010d}"


def best_checkpoint(env_steps: int) -> str:
    return f"best-{env_steps:010d}"


# -- writing whole or not at all ---------------------------------------------------------------------------


def fsync_file(path: Path) -> None:
    with open(path, "rb") as f:
        os.fsync(f.fileno())


def fsync_dir(path: Path) -> None:
    """Make a rename inside ``path`` durable: without it a crash may undo the rename after it returned."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def temporary(path: Path) -> Path:
    """Where ``path`` is written before it is renamed into place."""
    return path.with_name(f"{TMP_PREFIX}{path.name}")


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


def write_text(path: Path, text: str) -> None:
    """Write ``path`` whole or not at all: a kill mid-write leaves the old file or none."""
    tmp = temporary(path)
    tmp.write_text(text)
    os.replace(tmp, path)


def write_json(path: Path, data: dict[str, Any]) -> None:
    write_text(path, json.dumps(data, indent=1))


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
        try:
            targets.append(read_pointer(folder / name))
        except CheckpointError:
            pass
    return targets


# -- what a run folder holds -------------------------------------------------------------------------------


def checkpoint_steps(directory: Path) -> int | None:
    """The environment steps in a checkpoint's name, or None for a name that is not one."""
    match = _STEP_CHECKPOINT.fullmatch(directory.name) or _BEST_CHECKPOINT.fullmatch(directory.name)
    return int(match.group(1)) if match else None


def resumable_candidates(out: Path) -> list[Path]:
    """The run's resumable checkpoint directories (whole or not), newest first."""
    found = [
        directory
        for folder in out.iterdir()
        if folder.is_dir() and _STAGE_FOLDER.fullmatch(folder.name)
        for directory in folder.iterdir()
        if directory.is_dir() and _STEP_CHECKPOINT.fullmatch(directory.name)
    ]
    return sorted(found, key=lambda d: (checkpoint_steps(d), d.parent.name), reverse=True)


def is_leftover(entry: Path) -> bool:
    """Whether ``entry`` of a run folder is something a run writes before its first checkpoint, so that a
    folder holding nothing else can be started over without losing anything."""
    name = entry.name
    if name in (CONFIG, METRICS, REPORT, LOCK) or name.startswith(TMP_PREFIX) or name.startswith("events."):
        return True
    if entry.is_dir() and _STAGE_FOLDER.fullmatch(name):
        return all(child.name.startswith(TMP_PREFIX) for child in entry.iterdir())
    return False


def clear_leftovers(out: Path) -> None:
    """Remove what a run killed before its first checkpoint left in ``out`` (the lock file stays)."""
    for entry in out.iterdir():
        if entry.name != LOCK:
            shutil.rmtree(entry) if entry.is_dir() else entry.unlink()


def set_aside(out: Path, newer_than: int) -> list[Path]:
    """Move every checkpoint written after step ``newer_than`` into ``out/set-aside``, so a run resumed from
    an older checkpoint writes its own again; returns where they went. Nothing is deleted: a damaged
    checkpoint may be worth a look."""
    moved = []
    for folder in sorted(out.iterdir()):
        if not (folder.is_dir() and _STAGE_FOLDER.fullmatch(folder.name)):
            continue
        for directory in sorted(folder.iterdir()):
            steps = checkpoint_steps(directory)
            if directory.is_dir() and steps is not None and steps > newer_than:
                target = out / SET_ASIDE / folder.name / directory.name
                n = 1
                while target.exists():
                    target = target.with_name(f"{directory.name}.{n}")
                    n += 1
                target.parent.mkdir(parents=True, exist_ok=True)
                os.replace(directory, target)
                moved.append(target)
    return moved


def repoint(out: Path, checkpoint: Path) -> None:
    """Point the run at ``checkpoint`` again after newer ones were set aside: ``latest`` and its stage's
    ``last`` name it, ``best`` the newest agent-only checkpoint not newer than it (or nothing)."""
    folder = checkpoint.parent
    bests = sorted(
        (d for d in folder.iterdir() if d.is_dir() and _BEST_CHECKPOINT.fullmatch(d.name)), key=checkpoint_steps
    )
    if bests:
        write_pointer(folder / BEST, bests[-1].name)
    elif (folder / BEST).exists():
        (folder / BEST).unlink()
    write_pointer(folder / LAST, checkpoint.name)
    write_pointer(out / LATEST, f"{folder.name}/{checkpoint.name}")
    for later in out.iterdir():
        if later.is_dir() and _STAGE_FOLDER.fullmatch(later.name) and later != folder and not any(later.iterdir()):
            later.rmdir()


# -- one writer --------------------------------------------------------------------------------------------


class RunLock:
    """The OS lock on a run folder's ``.lock`` that makes its holder the folder's only writer."""

    def __init__(self, out: Path) -> None:
        """Take the lock on ``out`` (made if missing), or raise a ``RunError`` naming the process that holds
        it; a folder this process cannot write in is refused here, before anything else is done."""
        try:
            out.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryFile(dir=out):
                pass
            self._file = open(out / LOCK, "a+")
        except OSError as error:
            raise RunError(
                f"cannot write in the run folder {out}: {error.strerror or error}. Make it writable, or copy the "
                "run to a folder you can write in and resume it there."
            ) from None
        try:
            fcntl.flock(self._file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._file.seek(0)
            holder = self._file.read().strip() or "another process"
            self._file.close()
            raise RunError(
                f"{out} is in use: {holder} is writing this run. Wait for it to end, or stop it "
                "(Ctrl-C, or kill -INT with its pid) and resume."
            ) from None
        self._file.truncate(0)
        self._file.write(f"process {os.getpid()}")
        self._file.flush()

    def release(self) -> None:
        """Let another writer in; the kernel does the same when the process ends."""
        if not self._file.closed:
            fcntl.flock(self._file, fcntl.LOCK_UN)
            self._file.close()


def lock_holder(out: Path) -> str | None:
    """Who holds the lock on ``out`` now (``process N``), or None when no one does, taking nothing: a sweep
    resumed at once after a kill waits for the trials of the killed one to be gone."""
    try:
        with open(out / LOCK) as file:
            try:
                fcntl.flock(file, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                return file.read().strip() or "another process"
            fcntl.flock(file, fcntl.LOCK_UN)
    except FileNotFoundError:
        pass
    return None


# -- metrics.csv -------------------------------------------------------------------------------------------


def metric_columns(header: list[str]) -> list[str]:
    """The columns of a ``metrics.csv`` whose header is ``header``: this version's, then those that only an
    older version wrote (kept, so no figure of an older run is lost)."""
    return [*METRIC_COLUMNS, *(column for column in header if column not in METRIC_COLUMNS)]


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
    header = METRIC_COLUMNS if new else _header(path)
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


# -- report.md ---------------------------------------------------------------------------------------------


def write_report(out: Path, curriculum: Curriculum, state: RunState) -> None:
    (out / REPORT).write_text(render_report(curriculum, state, out))


def render_report(curriculum: Curriculum, state: RunState, out: Path) -> str:
    """``report.md``: how each stage went, and its agents on held-out test episodes, in Markdown."""
    lines = [
        f"# {curriculum.name}: {curriculum.task}",
        "",
        f"Seed {curriculum.seed}, {curriculum.envs} environments; evaluation on {curriculum.eval.episodes} fresh "
        f"episodes every {curriculum.eval.every:,} steps; each stage's agents tested on "
        f"{curriculum.test.episodes} held-out episodes.",
        "",
        *_stage_lines(curriculum, state),
    ]
    tests = {}
    for result in state.results:
        path = out / stage_folder(result.index, curriculum.stages[result.index].name) / TEST
        if path.is_file():
            tests[result.index] = (result.name, json.loads(path.read_text()))
    if tests:
        lines += _test_lines(tests)
    return "\n".join(lines) + "\n"


def _stage_lines(curriculum: Curriculum, state: RunState) -> list[str]:
    lines = [
        "## Stages",
        "",
        "| stage | rule | steps | ended | evaluations | rule's value at the end | wall time |",
        "|---|---|---|---|---|---|---|",
    ]
    for result in state.results:
        stage = curriculum.stages[result.index]
        rule = "-"
        if stage.promote:
            p = stage.promote
            rule = f"{p.on} {'>=' if p.statistic == 'mean' else 'lower bound >='} {p.success:g}, {p.patience} pooled"
        lines.append(
            f"| {result.index + 1}. {result.name} | {rule} | {result.end - result.start:,} of "
            f"{stage.budget.steps:,} | {result.ended} | {result.evaluations} | {_percent(result.rule_value)} | "
            f"{result.wall_time / 60:.1f} min |"
        )
    total = state.results[-1].end if state.results else 0
    status = FINISHED if state.finished else "running"
    if state.stopped_early:
        status = STOPPED_BY_BUDGET
    return lines + ["", f"{STATUS}{status}. {total:,} environment steps in all. (Wall time is cumulative.)"]


def run_ended(out: Path) -> bool:
    """Whether the run in ``out`` has ended, as its ``report.md`` says once the last stage's tests are written: a
    run killed after its last checkpoint but before those tests has not, and resuming it completes them."""
    path = out / REPORT
    if not path.is_file():
        return False
    ended = tuple(f"{STATUS}{status}." for status in (FINISHED, STOPPED_BY_BUDGET))
    return any(line.startswith(ended) for line in path.read_text().splitlines())


def _test_lines(tests: dict[int, tuple[str, dict[str, Any]]]) -> list[str]:
    """The tables of the stages' ``test.json`` records, ``tests`` keyed by stage index."""
    lines = [
        "",
        "## Test: held-out episodes",
        "",
        "Success with 95% Wilson interval (episodes). Nothing in the run was selected on these episodes. "
        "Per kind and after a negation: success on the episodes in which that correction was spoken.",
        "",
        "| stage | agent | success | correction episodes | corrected | ambiguity | common ground | "
        "instruction correction | wrong object | after a negation |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for index, (name, record) in tests.items():
        lines += _test_rows(index, name, record)
    language = next((record[LANGUAGE] for _, record in reversed(tests.values()) if LANGUAGE in record), None)
    if language:
        lines += [
            "",
            "## Language check: the final agent on plain test episodes",
            "",
            "`true`: the instructor's sentence; `blank`: no words; `other`: a sentence naming another object, "
            "won when the task holds for that object. An agent that reads its instruction is near chance "
            "with `blank` and about as good with `other` as with `true`.",
            "",
            "| instruction | success |",
            "|---|---|",
        ]
        for shown, r in language.items():
            overall = {"episodes": r["episodes"], "success": r["success"], "ci": r["success_ci"]}
            lines.append(f"| {shown} | {with_interval(overall)} |")
    corrections = next(
        (record[CORRECTION_TEST] for _, record in reversed(tests.values()) if CORRECTION_TEST in record), None
    )
    if corrections:
        lines += correction_test_lines(corrections)
    final = next((record for _, record in reversed(tests.values()) if SPLITS in record), None)
    if final:
        lines += split_lines(final[SPLITS], {agent: final[agent] for agent in (LAST, BEST) if agent in final})
    return lines


def correction_test_lines(records: dict[str, dict[str, Any]]) -> list[str]:
    """The section of ``report.md`` on the correction test of the final stage's agents (``records`` by agent)."""
    split = [figure for figure in FIGURES if figure.split]
    quota = next(iter(records.values()))["quota"]
    negations = f" and {quota['negations']} negations" if quota["negations"] else ""
    lines = [
        "",
        "## Correction test: the final stage's agents on correction episodes",
        "",
        "Every episode a correction episode (half the spoken corrections negations, where the stage has them), "
        f"run until {quota['spoken']} corrections{negations} were spoken, or for {quota['episodes']} episodes; "
        "episodes of their own, apart from the test's. Success where a correction was spoken, with 95% Wilson "
        f"interval (spoken); per kind and form: success (spoken), `*` where fewer than {JUDGED} were spoken: "
        "shown, not judged.",
        "",
        "| agent | episodes | corrected | " + " | ".join(figure.label for figure in split) + " |",
        "|---|---|---|" + "---|" * len(split),
    ]
    for agent, r in records.items():
        cells = [_judged(*figure.read(r)) for figure in split]
        met = "" if r["quota_met"] else ", quota not met"
        lines.append(
            f"| {agent} ({r['checkpoint'].split('/')[-1]}) | {r['episodes']}{met} | {with_interval(r['corrected'])} | "
            + " | ".join(cells) + " |"
        )
    attention = {agent: r[ATTENTION] for agent, r in records.items() if r.get(ATTENTION)}
    if attention:
        lines += [
            "",
            "Share of the actor's attention on the goal object, mean over steps: before any correction (plain), "
            "and after a correction of each form.",
            "",
            "| agent | " + " | ".join(PHASES) + " |",
            "|---|" + "---|" * len(PHASES),
        ]
        for agent, shares in attention.items():
            lines.append(f"| {agent} | " + " | ".join(_share(shares.get(phase)) for phase in PHASES) + " |")
    return lines


def _judged(episodes: int, success: float | None) -> str:
    """A kind's or form's success as ``75% (40)``, marked ``*`` on too few spoken corrections to judge it."""
    if not episodes or success is None:
        return "-"
    return f"{100 * success:.0f}% ({episodes}){'*' if episodes < JUDGED else ''}"


def _share(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _test_rows(index: int, name: str, record: dict[str, Any]) -> list[str]:
    rows = []
    for agent in (LAST, BEST):
        if agent not in record:
            continue
        r = record[agent]
        overall = {"episodes": r["episodes"], "success": r["success"], "ci": r["success_ci"]}
        episodes = {
            "episodes": r["correction_episodes"],
            "success": r["correction_episode_success"],
            "ci": r["correction_episode_success_ci"],
        }
        kinds = [_with_count(r["by_kind"].get(kind.value, {}).get("corrected")) for kind in Kind]
        rows.append(
            f"| {index + 1}. {name} | {agent} ({r['checkpoint'].split('/')[-1]}) | {with_interval(overall)} | "
            f"{with_interval(episodes)} | {with_interval(r['corrected'])} | {' | '.join(kinds)} | "
            f"{_with_count(r['by_negation']['with_negation'])} |"
        )
    return rows


def _percent(value: float | None) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{100 * value:.0f}%"


def _with_count(rate: dict[str, Any] | None) -> str:
    return "-" if not rate or not rate["episodes"] else f"{100 * rate['success']:.0f}% ({rate['episodes']})"
