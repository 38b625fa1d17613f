"""Trained agents that ship with lanro, so that ``lanro eval push`` and ``lanro play push`` work right after
install, before any training.

Each is a checkpoint directory of the package's ``pretrained`` folder (the repository's top-level
``pretrained/`` links there), named like the curriculum whose final agent it is. It holds the policy alone
(:meth:`SACAgent.policy_state_dict`) and says where it came from in its state's ``extra["pretrained"]``:
the commit, the run's seed, the checkpoint, and the figures of its held-out test and correction test.
``lanro export`` writes one.
"""

from __future__ import annotations

import dataclasses
import json
from importlib.resources import files
from pathlib import Path
from typing import Any

from lanrocli.agent.sac import SACAgent
from lanrocli.train.checkpoint import load_checkpoint, resolve_checkpoint, save_checkpoint
from lanrocli.train.errors import CheckpointError
from lanrocli.train.runfolder import CORRECTION_TEST, SPLITS, TEST
from lanrocli.train.testset import checkpoint_name

PROVENANCE = "pretrained"
"""The key of a shipped agent's ``extra`` that says where it came from."""


def packaged_agents() -> dict[str, Path]:
    """The shipped agents by name."""
    folder = Path(str(files("lanrocli.pretrained")))
    return {entry.name: entry for entry in sorted(folder.iterdir()) if (entry / "agent.pt").is_file()}


def agent_path(given: Path) -> Path:
    """``given`` where it exists; else the shipped agent of that name; else a CheckpointError that lists them."""
    if given.exists():
        return given
    shipped = packaged_agents()
    if given.name == str(given) and given.name in shipped:
        return shipped[given.name]
    names = ", ".join(shipped) or "none"
    raise CheckpointError(f"{given} does not exist, and no agent ships under that name (those that do: {names})")


def provenance(directory: Path) -> dict[str, Any] | None:
    """Where a shipped agent came from, or None for a checkpoint of one's own run."""
    return load_checkpoint(directory, resumable=False).extra.get(PROVENANCE)


def export_agent(source: Path, out: Path, commit: str) -> Path:
    """Write the policy of the checkpoint ``source`` (a checkpoint, pointer or run folder) to ``out``, with
    its provenance: ``commit`` and the figures its run's test found for it."""
    directory = resolve_checkpoint(source)
    contents = load_checkpoint(directory, resumable=False)
    agent = SACAgent.from_state_dict(contents.agent)
    name = checkpoint_name(directory)
    origin = {
        "commit": commit,
        "seed": contents.train_settings["seed"],
        "checkpoint": name,
        **_tested(directory.parent / TEST, name),
    }
    slim = dataclasses.replace(contents, agent=agent.policy_state_dict(), extra={**contents.extra, PROVENANCE: origin})
    return save_checkpoint(out, slim)


def _tested(test: Path, name: str) -> dict[str, Any]:
    """The test figures its stage's ``test.json`` holds for the checkpoint ``name``: success overall and where
    a correction was spoken, on the test and the correction test, and each split's."""
    if not test.is_file():
        raise CheckpointError(f"{test} is missing: export the agent of a stage whose tests have run")
    record = json.loads(test.read_text())
    agent = next((a for a, r in record.items() if isinstance(r, dict) and r.get("checkpoint") == name), None)
    if agent is None:
        raise CheckpointError(f"{test} holds no test of {name}: export a stage's last or best agent")
    figures: dict[str, Any] = {"test": _figures(record[agent])}
    if agent in record.get(CORRECTION_TEST, {}):
        figures[CORRECTION_TEST] = _figures(record[CORRECTION_TEST][agent])
    for split, records in record.get(SPLITS, {}).items():
        if agent in records:
            figures[f"split_{split}"] = _figures(records[agent])
    return figures


def _figures(record: dict[str, Any]) -> dict[str, Any]:
    corrected = record["corrected"]
    return {
        "episodes": record["episodes"],
        "success": record["success"],
        "corrected_episodes": corrected["episodes"],
        "corrected_success": corrected["success"],
    }
