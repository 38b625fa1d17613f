"""A sweep's definition and its folder: the curriculum, the seeds, the settings changed for every trial and
the grid, the trials they make, and ``sweep.yaml``, which records them.

Settings are read as every command reads ``KEY=VALUE`` (:mod:`lanrocli.config.overrides`): by the
curriculum's own key paths, values as YAML. Every trial's curriculum is built and validated before any
trial starts, each problem located at the option that caused it, so a grid with one bad value is refused as
a whole.

The sweep folder holds one ordinary run folder per trial, named from its settings and seed
(``agent.critics=2,seed=0``), and ``sweep.yaml``. A resumed sweep must be the sweep that was started: its
record is compared with the one the command line makes, and a difference is refused with a diff, as a run
refuses a changed curriculum.

Nothing here loads torch, pybullet or Ray.
"""

from __future__ import annotations

import copy
import difflib
import itertools
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from lanrocli.config.curriculum import Curriculum, CurriculumError
from lanrocli.config.overrides import apply_settings, parse_key, read_settings, read_value, show, split_setting
from lanrocli.config.yamlfile import Problem
from lanrocli.sweep.protocol import TrialJob
from lanrocli.train.report import run_ended
from lanrocli.train.writing import LOCK, write_text

SWEEP_FILE = "sweep.yaml"
STOP_FILE = ".stop"
"""Made in the sweep folder to ask every running trial to write a checkpoint and stop."""
RAY_FOLDER = ".ray"
"""Ray Tune's own records of the sweep's trials (their logs and error tracebacks); nothing resumes from it."""

_UNSAFE = re.compile(r"[^A-Za-z0-9._+-]+")


class SweepError(ValueError):
    """A sweep that cannot start or resume as asked: its options, its folder or its record."""


def split_values(text: str) -> list[str]:
    """``a,[b,c],d`` as ``["a", "[b,c]", "d"]``: commas inside brackets or braces belong to the value."""
    values, depth, current = [], 0, ""
    for char in text:
        depth += char in "[{"
        depth -= char in "]}"
        if char == "," and depth == 0:
            values.append(current)
            current = ""
        else:
            current += char
    return [*values, current]


# -- the sweep ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Trial:
    """One run of the sweep: a seed and one value of every grid key."""

    name: str
    seed: int
    settings: dict[str, Any]


@dataclass(frozen=True)
class SweepSpec:
    """What a sweep runs: every trial follows from it, and ``sweep.yaml`` records it."""

    curriculum: str
    """The curriculum as the command line named it (information only: ``plan`` holds what it said)."""
    quick: bool
    seeds: tuple[int, ...]
    changes: dict[str, Any]
    """``--set``: key path -> value, for every trial."""
    grid: dict[str, tuple[Any, ...]]
    """``--grid``: key path -> values, one trial per combination and seed."""
    plan: dict[str, Any]
    """The curriculum resolved (``extends`` applied, defaults filled in, ``--quick`` scaled), before the
    changes and the grid."""

    @classmethod
    def from_options(
        cls, base: Curriculum, curriculum: str, quick: bool, seeds: list[str], sets: list[str], grids: list[str]
    ) -> SweepSpec:
        """The sweep the command line asks for; a malformed option is a ``SweepError``, or a ``SettingError``
        for ``--set`` and ``--grid`` as every command reads them, naming it."""
        chosen: list[int] = []
        for text in seeds:
            for part in text.split(","):
                if not part.strip().isdigit():
                    raise SweepError(f"--seeds {text}: {part.strip()!r} is not a seed (a whole number from 0)")
                if int(part) in chosen:
                    raise SweepError(f"--seeds: seed {int(part)} is given twice")
                chosen.append(int(part))
        changes = read_settings("--set", sets, "--seeds")
        grid: dict[str, tuple[Any, ...]] = {}
        for text in grids:
            key, value = split_setting("--grid", text, "--seeds")
            if key in grid or key in changes:
                raise SweepError(f"--grid {key} is given twice, or also with --set")
            values = tuple(read_value(f"--grid {text}", part) for part in split_values(value))
            if len({show(v) for v in values}) < len(values):
                raise SweepError(f"--grid {text}: a value is given twice")
            grid[key] = values
        plan = yaml.safe_load(base.to_yaml())
        return cls(curriculum, quick, tuple(chosen) or (base.seed,), changes, grid, plan)

    def trials(self) -> list[Trial]:
        """Every combination of the grid's values, times the seeds, in the order given."""
        trials, names = [], {}
        for combination in itertools.product(*self.grid.values()):
            settings = dict(zip(self.grid, combination))
            for seed in self.seeds:
                name = ",".join([*(f"{_folder_key(k)}={_safe(show(v))}" for k, v in settings.items()), f"seed={seed}"])
                if name in names:
                    raise SweepError(
                        f"the trials {names[name]} and {settings} would share the folder {name}: make the grid's "
                        "values differ in letters or digits"
                    )
                names[name] = settings
                trials.append(Trial(name, seed, dict(settings)))
        return trials

    def resolve(self) -> list[tuple[Trial, Curriculum]]:
        """Every trial with its curriculum, all validated first: a ``CurriculumError`` lists every problem of
        every trial (each once), located at the option that caused it where it can be."""
        problems: list[Problem] = []
        resolved = []
        for trial in self.trials():
            data = copy.deepcopy(self.plan)
            data["seed"] = trial.seed
            settings = [("--set", k, v) for k, v in self.changes.items()] + [
                ("--grid", k, v) for k, v in trial.settings.items()
            ]
            try:
                resolved.append((trial, apply_settings(Curriculum, data, settings, self.curriculum)))
            except CurriculumError as error:
                problems.extend(error.problems)
        if problems:
            raise CurriculumError(list(dict.fromkeys(problems)))
        return resolved

    # -- sweep.yaml ----------------------------------------------------------------------------------------

    def record(self) -> dict[str, Any]:
        return {
            "curriculum": self.curriculum,
            "quick": self.quick,
            "seeds": list(self.seeds),
            "set": self.changes,
            "grid": {key: list(values) for key, values in self.grid.items()},
            "trials": [{"name": t.name, "seed": t.seed, "settings": t.settings} for t in self.trials()],
            "plan": self.plan,
        }

    def to_yaml(self) -> str:
        header = (
            "# A lanro sweep: each trial below is an ordinary run folder beside this file.\n"
            "# Continue it with 'lanro sweep --out FOLDER --resume'; aggregate it with 'lanro report FOLDER'.\n"
        )
        return header + yaml.safe_dump(self.record(), sort_keys=False)

    @classmethod
    def read(cls, path: Path) -> SweepSpec:
        try:
            data = yaml.safe_load(path.read_text(encoding="utf-8"))
            spec = cls(
                curriculum=str(data["curriculum"]),
                quick=bool(data["quick"]),
                seeds=tuple(int(seed) for seed in data["seeds"]),
                changes=dict(data["set"]),
                grid={str(key): tuple(values) for key, values in data["grid"].items()},
                plan=dict(data["plan"]),
            )
            spec.trials()
        except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError, ValueError, AttributeError) as error:
            raise SweepError(f"{path} is not a readable sweep record ({type(error).__name__}: {error})") from None
        return spec

    def differences(self, other: SweepSpec, label: str, other_label: str) -> str:
        """What differs between two sweeps (the curriculum's file name aside); empty if they are the same."""
        mine, theirs = ({k: v for k, v in s.record().items() if k != "curriculum"} for s in (self, other))
        lines = difflib.unified_diff(
            yaml.safe_dump(mine, sort_keys=False).splitlines(keepends=True),
            yaml.safe_dump(theirs, sort_keys=False).splitlines(keepends=True),
            fromfile=label,
            tofile=other_label,
        )
        return "".join(lines)


def _safe(text: str) -> str:
    return _UNSAFE.sub("-", text)


def _folder_key(key: str) -> str:
    """A key path as part of a folder name: ``stages[0].budget.steps`` as ``stages.0.budget.steps``, as a
    shell would read brackets as a pattern."""
    return _safe(".".join(str(part) for part in parse_key(key)))


# -- the sweep folder --------------------------------------------------------------------------------------


def open_sweep(out: Path, spec: SweepSpec | None, resume: bool) -> SweepSpec:
    """The sweep to run in ``out``. A new one (``resume`` False) needs an empty or missing folder and is
    recorded there; a resumed one is the recorded one, which ``spec``, when given, must equal."""
    record = out / SWEEP_FILE
    if resume:
        if not record.is_file():
            raise SweepError(f"{out} holds no sweep to resume ({SWEEP_FILE} is missing); start one without --resume")
        saved = SweepSpec.read(record)
        if spec is not None:
            changes = saved.differences(spec, f"{record} (the sweep's)", "the sweep given now")
            if changes:
                raise SweepError(
                    "the sweep differs from the one started in this folder, so it was not resumed. Resume with the "
                    "same file and options (or with --out and --resume alone), or start a new sweep with another "
                    "--out.\n" + changes
                )
        (out / STOP_FILE).unlink(missing_ok=True)
        return saved
    if spec is None:
        raise SweepError("give a curriculum file to start a sweep")
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise SweepError(
            f"{out} is not empty. Continue the sweep there with --resume, or choose another folder with --out."
        )
    out.mkdir(parents=True, exist_ok=True)
    write_text(record, spec.to_yaml())
    return spec


def trial_started(folder: Path) -> bool:
    """Whether a trial's run folder holds anything a run wrote, so that it is resumed rather than started."""
    return folder.is_dir() and any(entry.name != LOCK for entry in folder.iterdir())


def trial_jobs(out: Path, trials: list[tuple[Trial, Curriculum]], device: str) -> list[TrialJob]:
    """The trials of the sweep in ``out`` whose runs have not ended, as jobs for Ray: a resumed sweep leaves
    the others alone."""
    stop_file = str((out / STOP_FILE).resolve())
    return [
        TrialJob(trial.name, str((out / trial.name).resolve()), plan.to_yaml(), device, stop_file)
        for trial, plan in trials
        if not run_ended(out / trial.name)
    ]
