"""Checkpoints as data: tensors in a weights-only torch file, everything else in JSON and numpy archives.

A checkpoint is a directory written under a temporary name, every file fsynced, then renamed into place;
only after that does the small ``latest`` pointer file change, again by an atomic rename. A kill at any
moment therefore leaves the previous checkpoint and the pointer to it whole. Loading uses
``torch.load(weights_only=True)`` and ``np.load(allow_pickle=False)``, so a file from a stranger cannot
run code.
"""

from __future__ import annotations

import json
import os
import pickle
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lanrocli.agent import ReplayBuffer

AGENT_FILE = "agent.pt"
BUFFER_FILE = "buffer.npz"
STATE_FILE = "state.json"
PARTIAL_FILE = "partial.npz"
LATEST = "latest"
TMP_PREFIX = ".tmp-"


class CheckpointError(RuntimeError):
    """A checkpoint is missing, incomplete, or not plain data."""


def _fsync_file(path: Path) -> None:
    with open(path, "rb") as f:
        os.fsync(f.fileno())


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_pointer(pointer: Path, target: str) -> None:
    """Point ``pointer`` (a small text file) at ``target`` atomically."""
    tmp = pointer.with_name(f"{TMP_PREFIX}{pointer.name}")
    tmp.write_text(target + "\n")
    _fsync_file(tmp)
    os.replace(tmp, pointer)
    _fsync_dir(pointer.parent)


def read_pointer(pointer: Path) -> Path:
    if not pointer.is_file():
        raise CheckpointError(f"no checkpoint pointer at {pointer}")
    return pointer.parent / pointer.read_text().strip()


def resolve_checkpoint(path: Path) -> Path:
    """The checkpoint directory that ``path`` names: a checkpoint itself, a pointer file (``latest``,
    ``best``, ``last``) or a run folder, meaning its latest checkpoint."""
    if path.is_dir() and (path / AGENT_FILE).is_file():
        return path
    if path.is_dir() and (path / LATEST).is_file():
        return resolve_checkpoint(read_pointer(path / LATEST))
    if path.is_file():
        return resolve_checkpoint(read_pointer(path))
    if not path.exists():
        raise CheckpointError(f"{path} does not exist")
    raise CheckpointError(
        f"{path} is neither a checkpoint (a directory with {AGENT_FILE}), a pointer file such as 'latest', "
        f"nor a run folder with a '{LATEST}' pointer"
    )


def save_checkpoint(
    directory: Path,
    agent_state: dict[str, Any],
    buffer: ReplayBuffer | None,
    state: dict[str, Any],
    partials: list[dict[str, np.ndarray]] | None,
) -> Path:
    """Write a checkpoint at ``directory`` (which must not exist yet) and return it.

    Without ``buffer`` and ``partials`` it holds the agent and the state only: enough to evaluate, not to
    resume."""
    if directory.exists():
        raise CheckpointError(f"checkpoint {directory} exists already; checkpoints are never overwritten")
    directory.parent.mkdir(parents=True, exist_ok=True)
    tmp = directory.with_name(f"{TMP_PREFIX}{directory.name}")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir()
    torch.save(agent_state, tmp / AGENT_FILE)
    (tmp / STATE_FILE).write_text(json.dumps(state, indent=1))
    names = [AGENT_FILE, STATE_FILE]
    if buffer is not None and partials is not None:
        buffer.save(tmp / BUFFER_FILE)
        arrays = {f"{i}/{key}": value for i, partial in enumerate(partials) for key, value in partial.items()}
        with open(tmp / PARTIAL_FILE, "wb") as f:
            np.savez(f, **arrays)
        names += [BUFFER_FILE, PARTIAL_FILE]
    for name in names:
        _fsync_file(tmp / name)
    _fsync_dir(tmp)
    os.replace(tmp, directory)
    _fsync_dir(directory.parent)
    return directory


def load_agent_state(directory: Path, device: str | torch.device = "cpu") -> dict[str, Any]:
    """The agent's tensors and plain data; refuses a file that would need to unpickle objects."""
    path = directory / AGENT_FILE
    if not path.is_file():
        raise CheckpointError(f"{directory} is not a checkpoint: {AGENT_FILE} is missing")
    try:
        return torch.load(path, map_location=device, weights_only=True)
    except pickle.UnpicklingError as error:
        raise CheckpointError(
            f"{path} holds Python objects other than tensors and plain data, so it was not loaded "
            f"(loading it could run code). Only checkpoints written by lanro are accepted. Detail: {error}"
        ) from None


def load_state(directory: Path) -> dict[str, Any]:
    """The plain data of a checkpoint: settings, counters, random states."""
    path = directory / STATE_FILE
    if not path.is_file():
        raise CheckpointError(f"{directory} is not a checkpoint: {STATE_FILE} is missing")
    return json.loads(path.read_text())


def load_checkpoint(
    directory: Path, device: str | torch.device = "cpu"
) -> tuple[dict[str, Any], ReplayBuffer, dict[str, Any], list[dict[str, np.ndarray]]]:
    """Everything a resumable checkpoint holds: agent state, replay buffer, state, unfinished episodes."""
    missing = [n for n in (AGENT_FILE, BUFFER_FILE, STATE_FILE, PARTIAL_FILE) if not (directory / n).is_file()]
    if missing:
        raise CheckpointError(
            f"{directory} cannot be resumed from: missing {', '.join(missing)} "
            "(a 'best' checkpoint holds the agent only, for evaluation)"
        )
    agent_state = load_agent_state(directory, device)
    buffer = ReplayBuffer.load(directory / BUFFER_FILE)
    state = load_state(directory)
    partials: dict[int, dict[str, np.ndarray]] = {}
    with np.load(directory / PARTIAL_FILE, allow_pickle=False) as archive:
        for name in archive.files:
            index, key = name.split("/", 1)
            partials.setdefault(int(index), {})[key] = archive[name]
    return agent_state, buffer, state, [partials[i] for i in sorted(partials)]


def prune(directory: Path, keep: set[Path]) -> None:
    """Remove checkpoint directories under ``directory`` except ``keep``, and stale temporary ones."""
    kept = {k.resolve() for k in keep}
    for child in directory.iterdir():
        if child.is_dir() and child.resolve() not in kept:
            shutil.rmtree(child, ignore_errors=True)
