"""A checkpoint's ``manifest.json``: the format version and the size and SHA-256 of every other file, so a
truncated or altered file is found before it is read, and named."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from lanrocli.train.errors import CheckpointError

MANIFEST_FILE = "manifest.json"
FORMAT = 2
"""The checkpoint format this version writes and reads."""


def write_manifest(directory: Path, names: list[str]) -> None:
    """The manifest of the files ``names`` of ``directory``, written after them so that it vouches for them."""
    manifest = {"format": FORMAT, "files": {name: fingerprint(directory / name) for name in names}}
    (directory / MANIFEST_FILE).write_text(json.dumps(manifest, indent=1))


def verify_checkpoint(directory: Path, names: tuple[str, ...]) -> None:
    """Check ``names`` against the checkpoint's manifest (size, then SHA-256). Raises a ``CheckpointError``
    naming the first damaged file, or the manifest where it is missing."""
    path = directory / MANIFEST_FILE
    if not path.is_file():
        raise CheckpointError(f"{directory} cannot be used: its {MANIFEST_FILE} is missing")
    try:
        manifest = json.loads(path.read_text())
        version, files = int(manifest["format"]), manifest["files"]
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        raise CheckpointError(f"{path} is damaged: it is not the manifest lanro writes") from None
    if version != FORMAT:
        raise CheckpointError(f"{directory} has checkpoint format {version}; this lanro reads format {FORMAT}")
    for name in names:
        expected = files.get(name)
        if expected is None:
            raise CheckpointError(f"{directory} cannot be used: its manifest lists no {name}")
        file = directory / name
        if not file.is_file():
            raise CheckpointError(f"{file} is missing")
        size = file.stat().st_size
        if size != expected["bytes"]:
            raise CheckpointError(f"{file} is damaged: {size:,} bytes where {expected['bytes']:,} were written")
        if fingerprint(file)["sha256"] != expected["sha256"]:
            raise CheckpointError(f"{file} is damaged: its contents differ from what was written (SHA-256)")


def fingerprint(path: Path) -> dict[str, Any]:
    """What the manifest keeps of a file to find it truncated or altered: its size, then its SHA-256."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return {"bytes": path.stat().st_size, "sha256": digest.hexdigest()}
