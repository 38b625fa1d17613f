"""A trained agent measured on episodes: by default its stage's held-out test episodes.

The run measures the ``last`` and ``best`` agents of every stage here when the stage ends, and ``lanro eval``
measures any checkpoint here, so the two give the same record for the same checkpoint and episodes: the
record is what ``test.json`` holds and what ``lanro eval --json`` prints.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from lanrocli.choices import Instruction
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.evaluation import EvaluationReport, evaluate
from lanrocli.envs.settings import EnvSettings
from lanrocli.train.checkpoint import resolve_checkpoint
from lanrocli.train.seeds import held_out_seed
from lanrocli.train.trainer import TrainSettings, load_policy


@dataclass(frozen=True)
class Measurement:
    """What one measurement of a checkpoint found, and the record of it for files and ``--json``."""

    settings: TrainSettings
    env: EnvSettings
    first_seed: int
    held_out: bool
    report: EvaluationReport
    record: dict[str, Any]


def checkpoint_name(directory: Path) -> str:
    """A checkpoint as its run names it (``stage-1-single/step-0000010000``), whatever path led to it."""
    return f"{directory.parent.name}/{directory.name}"


def measure(
    path: Path,
    episodes: int,
    device: str | torch.device = "cpu",
    overrides: Mapping[str, Any] | None = None,
    seed: int | None = None,
    instruction: Instruction = Instruction.TRUE,
    gif: Path | None = None,
    progress: Callable[[int], None] | None = None,
    check: Callable[[TrainSettings, EnvSettings], None] | None = None,
) -> Measurement:
    """Run the deterministic policy of the checkpoint at ``path`` (a checkpoint, pointer or run folder).

    The environment is the checkpoint's stage as evaluation sees it (neutral starts), changed by
    ``overrides`` (fields of ``EnvSettings``); the episodes are the stage's test episodes unless ``seed`` asks for others (episode i
    then uses ``seed + i``). ``check`` may refuse the resolved settings (raise) before anything runs.
    """
    directory = resolve_checkpoint(path)
    settings, policy = load_policy(directory, device)
    env_settings = settings.env.for_evaluation().replace(**(overrides or {}))
    if check is not None:
        check(settings, env_settings)
    held_out = seed is None
    first = held_out_seed(settings.seed, settings.stage) if seed is None else seed
    env = LanroEnv(settings.task, env_settings, object_slots=settings.slots, render_mode="rgb_array" if gif else None)
    try:
        report = evaluate(env, policy, episodes, first, gif, progress, instruction)
    finally:
        env.close()
    record = {
        "checkpoint": checkpoint_name(directory),
        "task": settings.task,
        "env": env_settings.to_dict(),
        "episodes_from": {"test_set": held_out, "first_seed": first},
        "instruction": instruction.value,
        **report.as_dict(),
    }
    return Measurement(settings, env_settings, first, held_out, report, record)
