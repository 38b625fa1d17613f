"""Which runs belong together: a sweep folder stands for its trials, and runs are grouped by their settings.

Runs whose resolved curricula (``config.yaml``) are equal but for the seed and the name are one group: the
seeds of one setting. Each ``config.yaml`` is read through the current curriculum schema, so a setting added
since an older run was trained reads as its default there, not as a difference. Groups are named by the keys
on which they differ (``agent.critics=2``), in the key paths of
``--set``; so the trials of a grid fall into one group per grid setting, and run folders trained one by one
group the same way. Runs without a ``config.yaml`` (a bare ``metrics.csv``) form one group of their own.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from lanrocli.config.curriculum import Curriculum
from lanrocli.config.overrides import flatten, show
from lanrocli.config.yamlfile import CurriculumError, validate
from lanrocli.sweep.plan import SWEEP_FILE, SweepSpec
from lanrocli.train.runfolder import CONFIG

IGNORED = ("seed", "name")
"""Keys whose values vary within a group: the name labels a curriculum and sets nothing."""


@dataclass(frozen=True)
class Group:
    label: str
    """The settings that set this group apart (``agent.critics=2, eval.episodes=50``); empty when all runs
    form one group."""
    settings: dict[str, Any]
    runs: tuple[Path, ...]


def expand(paths: list[Path]) -> list[Path]:
    """The run folders that ``paths`` name: a sweep folder's trials that have started, in the order of its
    record, and any other folder as itself."""
    runs: list[Path] = []
    for path in paths:
        if not path.exists():
            raise ValueError(f"{path} does not exist")
        if (path / SWEEP_FILE).is_file():
            trials = [path / trial.name for trial in SweepSpec.read(path / SWEEP_FILE).trials()]
            started = [trial for trial in trials if trial.is_dir()]
            if not started:
                raise ValueError(f"{path} is a sweep none of whose trials has started yet")
            runs += started
        else:
            runs.append(path)
    return list(dict.fromkeys(runs))


def _signature(run: Path) -> dict[str, Any] | None:
    config = run / CONFIG if run.is_dir() else None
    if config is None or not config.is_file():
        return None
    try:
        data = yaml.safe_load(config.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
        raise ValueError(f"{config} cannot be read: {error}") from None
    with contextlib.suppress(CurriculumError):  # one this version no longer reads is compared as written
        data = validate(Curriculum, data, {}, config).model_dump(mode="json")
    return {key: _plain(value) for key, value in flatten(data).items() if key not in IGNORED}


def _plain(value: Any) -> Any:
    """A whole float as an int: a setting that became a float (``updates_per_step``) is written ``1.0`` by
    newer runs and ``1`` by older ones, and the two are the same setting."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


def group_runs(paths: list[Path]) -> list[Group]:
    """The runs of ``paths`` (sweep folders expanded) in groups of equal settings, in order of appearance."""
    signatures: dict[str, tuple[dict[str, Any] | None, list[Path]]] = {}
    for run in expand(paths):
        signature = _signature(run)
        key = yaml.safe_dump(signature, sort_keys=True)
        signatures.setdefault(key, (signature, []))[1].append(run)
    known = [signature for signature, _ in signatures.values() if signature is not None]
    keys = dict.fromkeys(key for signature in known for key in signature)
    differing = [key for key in keys if len({show(signature.get(key)) for signature in known}) > 1]
    groups = []
    for signature, runs in signatures.values():
        if signature is None:
            settings: dict[str, Any] = {}
            label = "runs without config.yaml" if len(signatures) > 1 else ""
        else:
            settings = {key: signature.get(key) for key in differing}
            label = ", ".join(f"{key}={show(value)}" for key, value in settings.items())
        groups.append(Group(label, settings, tuple(runs)))
    return groups
