"""Files written whole or not at all, and the lock that makes one process a run folder's only writer.

Whatever may be read while a run is killed is replaced whole: it is written under a temporary name
(``TMP_PREFIX``), then renamed into place. The lock is an OS lock on ``.lock``, which the kernel releases when
the process ends however it ends, so a killed run never leaves a stale lock; readers do not take it.
"""

from __future__ import annotations

import fcntl
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from lanrocli.train.errors import RunError

TMP_PREFIX = ".tmp-"
LOCK = ".lock"


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


def write_text(path: Path, text: str) -> None:
    """Write ``path`` whole or not at all: a kill mid-write leaves the old file or none."""
    tmp = temporary(path)
    tmp.write_text(text)
    os.replace(tmp, path)


def write_json(path: Path, data: dict[str, Any]) -> None:
    write_text(path, json.dumps(data, indent=1))


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
            self._file = open(out / LOCK, "a+")  # noqa: SIM115 - held open: the lock lasts as long as the file
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
