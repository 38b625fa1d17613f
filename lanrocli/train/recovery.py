"""Recovery: what a run left in its folder when it was killed or its disk failed, and the folder put back
in order so that it continues.

Every state a kill, a full disk or a damaged file can leave continues with one of two commands: a folder
holding no checkpoint yet is started over by either a fresh start or ``--resume``; a damaged newest
checkpoint makes ``--resume`` fall back to the newest whole one, setting the newer ones aside. Each
checkpoint carries copies of ``config.yaml`` and ``metrics.csv`` as they were when it was written, so a
resumed run rewrites both from it, whatever happened to them since.

This module loads neither torch nor pybullet: the checkpoint is loaded by the function the caller passes.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from lanrocli.config.curriculum import Curriculum, CurriculumError, load_curriculum
from lanrocli.train.errors import CheckpointError, RunError
from lanrocli.train.runfolder import (
    BEST,
    BEST_CHECKPOINT,
    CONFIG,
    LAST,
    LATEST,
    METRICS,
    REPORT,
    SET_ASIDE,
    STAGE_FOLDER,
    STEP_CHECKPOINT,
    align_metrics,
    checkpoint_steps,
    read_pointer,
    truncate_metrics,
    write_pointer,
)
from lanrocli.train.writing import LOCK, TMP_PREFIX, RunLock, write_text

Loaded = TypeVar("Loaded")


def resumable_candidates(out: Path) -> list[Path]:
    """The run's resumable checkpoint directories (whole or not), newest first."""
    found = [
        directory
        for folder in out.iterdir()
        if folder.is_dir() and STAGE_FOLDER.fullmatch(folder.name)
        for directory in folder.iterdir()
        if directory.is_dir() and STEP_CHECKPOINT.fullmatch(directory.name)
    ]
    return sorted(found, key=lambda d: (checkpoint_steps(d), d.parent.name), reverse=True)


def is_leftover(entry: Path) -> bool:
    """Whether ``entry`` of a run folder is something a run writes before its first checkpoint, so that a
    folder holding nothing else can be started over without losing anything."""
    name = entry.name
    if name in (CONFIG, METRICS, REPORT, LOCK) or name.startswith(TMP_PREFIX) or name.startswith("events."):
        return True
    if entry.is_dir() and STAGE_FOLDER.fullmatch(name):
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
        if not (folder.is_dir() and STAGE_FOLDER.fullmatch(folder.name)):
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
        (d for d in folder.iterdir() if d.is_dir() and BEST_CHECKPOINT.fullmatch(d.name)), key=checkpoint_steps
    )
    if bests:
        write_pointer(folder / BEST, bests[-1].name)
    elif (folder / BEST).exists():
        (folder / BEST).unlink()
    write_pointer(folder / LAST, checkpoint.name)
    write_pointer(out / LATEST, f"{folder.name}/{checkpoint.name}")
    for later in out.iterdir():
        if later.is_dir() and STAGE_FOLDER.fullmatch(later.name) and later != folder and not any(later.iterdir()):
            later.rmdir()


def saved_plan(out: Path) -> Curriculum:
    """The curriculum a run without a checkpoint was started with, to start it over."""
    try:
        return load_curriculum(out / CONFIG)
    except (CurriculumError, OSError):
        raise RunError(
            f"{out} holds no checkpoint and no readable {CONFIG}: start it again with the curriculum file, "
            f"'lanro train CURRICULUM --out {out}' (what is there is replaced, as nothing was trained yet)"
        ) from None


def newest_whole(out: Path, candidates: list[Path], load: Callable[[Path], Loaded]) -> tuple[Path, Loaded, list[str]]:
    """The checkpoint to resume from, loaded: the one ``latest`` names when it is whole, else the newest
    whole one, whose checkpoints written later are then set aside. Raises ``RunError`` when none is whole."""
    problems: list[str] = []
    try:
        named = read_pointer(out / LATEST)
        if named.is_dir():
            candidates = [named, *(c for c in candidates if c != named)]
        else:
            problems.append(f"{out / LATEST} names {named.relative_to(out)}, which does not exist")
    except CheckpointError as error:
        problems.append(str(error))
    newest = max((checkpoint_steps(c) or 0 for c in candidates), default=0)
    for directory in candidates:
        try:
            loaded = load(directory)
        except CheckpointError as error:
            problems.append(str(error))
            continue
        notes = [f"damaged: {problem}" for problem in problems]
        steps = checkpoint_steps(directory) or 0
        if problems:
            notes.append(
                f"resuming from the newest whole checkpoint, {directory.parent.name}/{directory.name}: "
                f"{newest - steps:,} environment steps will be trained again"
            )
        moved = set_aside(out, steps)
        if moved:
            notes.append(
                f"{len(moved)} checkpoint(s) written after it were moved to {out / SET_ASIDE}; delete them when done"
            )
        if problems or moved:
            repoint(out, directory)
        return directory, loaded, notes
    listed = "\n".join(f"  {problem}" for problem in problems)
    raise RunError(
        f"{out} holds no whole checkpoint to resume from:\n{listed}\n"
        f"Start a new run with another --out, or delete {out} and start again."
    )


@contextmanager
def released_on_error(lock: RunLock) -> Iterator[None]:
    """Hold ``lock`` beyond the block only if it succeeds: a run that fails to open lets the folder go."""
    try:
        yield
    except BaseException:
        lock.release()
        raise


def restore_files(out: Path, directory: Path, extra: dict[str, Any], notes: list[str]) -> Curriculum:
    """Rewrite ``config.yaml`` and ``metrics.csv`` as the checkpoint at ``directory`` saw them (older
    checkpoints hold no copies: their metrics are cut back to the checkpoint's steps), and return the run's
    curriculum."""
    copies = extra.get("files", {})
    if CONFIG in copies:
        config = out / CONFIG
        current = config.read_text() if config.is_file() else None
        if current != copies[CONFIG]:
            notes.append(
                f"{config} was {'changed' if current is not None else 'missing'}: restored from the checkpoint"
            )
            write_text(config, copies[CONFIG])
    restore_metrics(out, directory, extra, notes)
    try:
        return load_curriculum(out / CONFIG)
    except (CurriculumError, OSError) as error:
        raise RunError(f"{out} holds no readable {CONFIG} and its checkpoint no copy of it: {error}") from None


def restore_metrics(out: Path, directory: Path, extra: dict[str, Any], notes: list[str]) -> None:
    """Rewrite ``out``'s ``metrics.csv`` as the checkpoint at ``directory`` saw it (from its copy, or, for
    an older checkpoint without one, the file cut back to the checkpoint's steps), in this version's columns."""
    copies = extra.get("files", {})
    if METRICS in copies:
        write_text(out / METRICS, copies[METRICS])
    else:
        truncate_metrics(out / METRICS, checkpoint_steps(directory) or 0)
    gained = align_metrics(out / METRICS)
    if gained:
        notes.append(
            f"{out / METRICS} was written by an older version: rewritten with {len(gained)} new column(s) "
            f"({', '.join(gained)}), empty in its earlier rows"
        )
