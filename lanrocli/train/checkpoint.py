"""Checkpoints as data: tensors in a weights-only torch file, everything else in JSON and numpy archives.

Everything a checkpoint holds is one :class:`Checkpoint`, and this module alone turns it into files and
back, so what a checkpoint contains is written down in one place. A checkpoint is a directory written under
a temporary name, every file fsynced, then renamed into place; the pointers that name it change only after
that (see :mod:`lanrocli.train.runfolder`). Loading uses ``torch.load(weights_only=True)`` and
``np.load(allow_pickle=False)``, so a file from a stranger cannot run code.

Each checkpoint ends with ``manifest.json`` (:mod:`lanrocli.train.manifest`), so a truncated or altered file
is found before it is read, and named. A write that fails (a full disk, a folder made read-only) removes its temporary
directory and says how much room the checkpoint needs; the checkpoints written before it stay whole.
"""

from __future__ import annotations

import errno
import io
import json
import os
import pickle
import shutil
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import torch

from lanrocli.agent.buffer.replay_buffer import ReplayBuffer
from lanrocli.agent.settings import SACSettings
from lanrocli.train.errors import CheckpointError
from lanrocli.train.manifest import MANIFEST_FILE, verify_checkpoint, write_manifest
from lanrocli.train.runfolder import LATEST, STATE_FILE, read_pointer
from lanrocli.train.writing import fsync_dir, fsync_file, temporary

AGENT_FILE = "agent.pt"
BUFFER_FILE = "buffer.npz"
PARTIAL_FILE = "partial.npz"
RESUMABLE_FILES = (AGENT_FILE, BUFFER_FILE, STATE_FILE, PARTIAL_FILE)

T = TypeVar("T")


@dataclass
class Checkpoint:
    """Everything a checkpoint holds. Without ``buffer``, ``partials`` and ``environments`` it holds the
    agent and the state only: enough to evaluate, a fraction of the size, but nothing to resume from."""

    agent: dict[str, Any]
    """The agent's state dict, which holds the only saved copy of the agent's settings."""
    train_settings: dict[str, Any]
    vocabulary: dict[str, Any]
    progress: dict[str, Any]
    rng: dict[str, Any]
    """The state of the trainer's sampling generator, as numpy's bit generator gives it."""
    wall_time: float
    extra: dict[str, Any]
    """The caller's plain data (a curriculum's position)."""
    buffer: ReplayBuffer | None = None
    partials: list[dict[str, np.ndarray]] | None = None
    """Each environment's unfinished episode as arrays."""
    environments: list[dict[str, Any]] | None = None
    """Each environment's snapshot, to rebuild it mid-episode."""
    clock: dict[str, Any] = field(default_factory=dict)
    """Where the run's time went (``PhaseClock``)."""

    def __post_init__(self) -> None:
        if len({part is None for part in (self.buffer, self.partials, self.environments)}) > 1:
            raise ValueError("a checkpoint holds its buffer, partial episodes and environments together or none")

    @property
    def agent_settings(self) -> SACSettings:
        return SACSettings.from_dict(self.agent["settings"])


def state_to_json(state: dict[str, Any]) -> dict[str, Any]:
    """A numpy bit-generator state for JSON: its 128-bit integers become strings, which every reader keeps."""
    return {
        k: state_to_json(v) if isinstance(v, dict) else (str(v) if isinstance(v, int) else v) for k, v in state.items()
    }


def state_from_json(state: dict[str, Any]) -> dict[str, Any]:
    return {
        k: state_from_json(v)
        if isinstance(v, dict)
        else (int(v) if isinstance(v, str) and v.lstrip("-").isdigit() else v)
        for k, v in state.items()
    }


# -- writing -----------------------------------------------------------------------------------------------


class CheckpointWriteError(CheckpointError):
    """A checkpoint could not be written; nothing of it was left behind."""


def save_checkpoint(directory: Path, contents: Checkpoint) -> Path:
    """Write ``contents`` as a checkpoint at ``directory`` (which must not exist yet) and return it."""
    if directory.exists():
        raise CheckpointError(f"checkpoint {directory} exists already; checkpoints are never overwritten")
    tmp = temporary(directory)
    try:
        directory.parent.mkdir(parents=True, exist_ok=True)
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir()
        _write_files(tmp, contents)
        fsync_dir(tmp)
        os.replace(tmp, directory)
        fsync_dir(directory.parent)
    except OSError as error:
        shutil.rmtree(tmp, ignore_errors=True)
        raise CheckpointWriteError(_write_failure(directory, contents, error)) from None
    return directory


def _write_files(tmp: Path, contents: Checkpoint) -> None:
    """Every file of the checkpoint into ``tmp``, fsynced, the manifest last."""
    # The agent is serialised in memory first: torch reports a failed write to disk as an opaque
    # RuntimeError, whereas a plain file write fails with the OSError that says what went wrong.
    agent = io.BytesIO()
    torch.save(contents.agent, agent)
    (tmp / AGENT_FILE).write_bytes(agent.getvalue())
    (tmp / STATE_FILE).write_text(json.dumps(_plain_state(contents), indent=1))
    names = [AGENT_FILE, STATE_FILE]
    if contents.buffer is not None and contents.partials is not None:
        _write_buffer(tmp / BUFFER_FILE, contents.buffer)
        _write_partials(tmp / PARTIAL_FILE, contents.partials)
        names += [BUFFER_FILE, PARTIAL_FILE]
    write_manifest(tmp, names)
    for name in [*names, MANIFEST_FILE]:
        fsync_file(tmp / name)


def _write_failure(directory: Path, contents: Checkpoint, error: OSError) -> str:
    """Why a checkpoint write failed, and what it needs, in words a user can act on."""
    needed = _size_bound(contents)
    where = directory.parent if directory.parent.exists() else directory.parent.parent
    try:
        free = f"{shutil.disk_usage(where).free / 2**20:,.1f} MB are free there"
    except OSError:
        free = "the free space there is unknown"
    reason = error.strerror or str(error)
    if error.errno in (errno.ENOSPC, errno.EDQUOT):
        advice = "free some space (or move the run folder to a larger disk)"
    elif error.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
        advice = "make the run folder writable again"
    else:
        advice = "fix the cause"
    return (
        f"could not write checkpoint {directory}: {reason}. Checkpoints written before it are whole. "
        f"It needs up to {needed / 2**20:,.1f} MB; {free}. Then {advice} and resume."
    )


def _size_bound(contents: Checkpoint) -> int:
    """Bytes a checkpoint of ``contents`` takes at most (its arrays uncompressed)."""
    agent = sum(t.numel() * t.element_size() for t in _tensors(contents.agent))
    arrays = 0
    if contents.buffer is not None and contents.partials is not None:
        arrays = sum(a.nbytes for a in contents.buffer.state()[1].values())
        arrays += sum(a.nbytes for partial in contents.partials for a in partial.values())
    return agent + arrays + len(json.dumps(_plain_state(contents))) + 2**16


def _tensors(value: Any) -> list[torch.Tensor]:
    if isinstance(value, torch.Tensor):
        return [value]
    if isinstance(value, dict):
        return [t for v in value.values() for t in _tensors(v)]
    if isinstance(value, (list, tuple)):
        return [t for v in value for t in _tensors(v)]
    return []


def _plain_state(contents: Checkpoint) -> dict[str, Any]:
    """What ``state.json`` holds: everything but the agent and the arrays."""
    state = {
        "train_settings": contents.train_settings,
        "vocabulary": contents.vocabulary,
        "progress": contents.progress,
        "rng": state_to_json(contents.rng),
        "wall_time": contents.wall_time,
        "extra": contents.extra,
        "clock": contents.clock,
    }
    if contents.environments is not None:
        state["environments"] = contents.environments
    return state


def _write_buffer(path: Path, buffer: ReplayBuffer) -> None:
    meta, arrays = buffer.state()
    with open(path, "wb") as f:
        np.savez_compressed(f, meta=np.array(json.dumps(meta)), **arrays)


def _write_partials(path: Path, partials: list[dict[str, np.ndarray]]) -> None:
    arrays = {f"{i}/{key}": value for i, partial in enumerate(partials) for key, value in partial.items()}
    with open(path, "wb") as f:
        np.savez(f, **arrays)


# -- reading -----------------------------------------------------------------------------------------------


def load_checkpoint(directory: Path, device: str | torch.device = "cpu", resumable: bool = True) -> Checkpoint:
    """The checkpoint at ``directory``; with ``resumable`` all of it, and an error if it cannot be resumed
    from, else its agent and state only (the buffer, which may be large, is not read). A damaged file is
    a ``CheckpointError`` that names it."""
    if resumable:
        missing = [n for n in RESUMABLE_FILES if not (directory / n).is_file()]
        if missing:
            raise CheckpointError(
                f"{directory} cannot be resumed from: missing {', '.join(missing)} "
                "(a 'best' checkpoint holds the agent only, for evaluation)"
            )
    verify_checkpoint(directory, RESUMABLE_FILES if resumable else (AGENT_FILE, STATE_FILE))
    state = _load_state(directory)
    agent = load_agent_state(directory, device)
    try:
        return Checkpoint(
            agent=agent,
            train_settings=state["train_settings"],
            vocabulary=state["vocabulary"],
            progress=state["progress"],
            rng=state_from_json(state["rng"]),
            wall_time=float(state["wall_time"]),
            extra=state["extra"],
            clock=state["clock"],
            buffer=_reading(directory / BUFFER_FILE, _read_buffer) if resumable else None,
            partials=_reading(directory / PARTIAL_FILE, _read_partials) if resumable else None,
            environments=state["environments"] if resumable else None,
        )
    except (KeyError, TypeError, ValueError) as error:
        raise CheckpointError(f"{directory / STATE_FILE} is damaged: {error!r} is missing or wrong") from None


def _reading(path: Path, read: Callable[[Path], T]) -> T:
    """``read(path)``, with whatever a damaged archive raises as a ``CheckpointError`` naming the file."""
    try:
        return read(path)
    except (OSError, EOFError, ValueError, KeyError, zipfile.BadZipFile) as error:
        raise CheckpointError(f"{path} is damaged: {error}") from None


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
    except (RuntimeError, EOFError, OSError, ValueError) as error:
        raise CheckpointError(f"{path} is damaged: {error}") from None


def _load_state(directory: Path) -> dict[str, Any]:
    path = directory / STATE_FILE
    if not path.is_file():
        raise CheckpointError(f"{directory} is not a checkpoint: {STATE_FILE} is missing")
    try:
        state = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as error:
        raise CheckpointError(f"{path} is damaged: {error}") from None
    if not isinstance(state, dict):
        raise CheckpointError(f"{path} is damaged: it holds no object")
    return state


def _read_buffer(path: Path) -> ReplayBuffer:
    # The open archive is handed over as it is, so each array is read only as the buffer copies it in.
    with np.load(path, allow_pickle=False) as archive:
        return ReplayBuffer.from_state(json.loads(str(archive["meta"])), archive)


def _read_partials(path: Path) -> list[dict[str, np.ndarray]]:
    partials: dict[int, dict[str, np.ndarray]] = {}
    with np.load(path, allow_pickle=False) as archive:
        for name in archive.files:
            index, key = name.split("/", 1)
            partials.setdefault(int(index), {})[key] = archive[name]
    return [partials[i] for i in sorted(partials)]


def resolve_checkpoint(path: Path) -> Path:
    """The checkpoint directory that ``path`` names: a checkpoint itself, a pointer file (``latest``,
    ``best``, ``last``) or a run folder, meaning its latest checkpoint. A pointer names a checkpoint
    directory, never another pointer."""
    if path.is_dir() and (path / AGENT_FILE).is_file():
        return path
    if not path.exists():
        raise CheckpointError(f"{path} does not exist")
    pointer = path / LATEST if path.is_dir() and (path / LATEST).is_file() else path
    if not pointer.is_file():
        raise CheckpointError(
            f"{path} is neither a checkpoint (a directory with {AGENT_FILE}), a pointer file such as 'latest', "
            f"nor a run folder with a '{LATEST}' pointer"
        )
    target = read_pointer(pointer)
    if not (target.is_dir() and (target / AGENT_FILE).is_file()):
        raise CheckpointError(
            f"{pointer}, read as a pointer such as RUN/latest, names {target}, which is not a checkpoint"
        )
    return target
