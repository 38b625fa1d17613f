"""Curricula: YAML files of training stages, checked completely before any physics runs.

A file describes the task, the agent's settings, how often to evaluate and a list of stages, each with its
environment, step budget and the rule that promotes the agent to the next stage. Everything wrong with a
file is reported at once, each problem with its file, line and key path, so one edit fixes them all.

``extends: other.yaml`` (top level only; the path is relative to the directory of the file that names it)
builds a file on top of another, in chains of any length. The merge rule: mappings merge key by key,
recursively; every other value, lists included, replaces the parent's value wholesale. So a child that
sets ``agent: {batch_size: 128}`` keeps the parent's other agent settings, while a child that sets
``stages`` replaces all of the parent's stages: merging stage lists item by item would make the result
depend on positions the child cannot see.
"""

from __future__ import annotations

import dataclasses
import difflib
import re
import typing
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NamedTuple

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    create_model,
    field_validator,
    model_validator,
)
from pydantic_core import ErrorDetails

from lanrocli.agent import SACSettings
from lanrocli.envs.instructor import InstructorSettings, Kind
from lanrocli.train.seeds import FIELD

KindName = Literal["ambiguity", "common_ground", "instruction_correction", "wrong_object"]
TaskName = Literal["reach", "push", "grasp", "lift"]
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]*$"
"""Curriculum and stage names become folder names: no separators, no leading dot."""

KeyPath = tuple[str | int, ...]

QUICK_TEST_EPISODES = 40
"""Test episodes per agent and stage under ``--quick``: enough to see the pipeline work, in seconds."""


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a curriculum, located as precisely as the file allows."""

    file: Path | str
    line: int | None
    path: str
    message: str

    def __str__(self) -> str:
        where = str(self.file) if self.line is None else f"{self.file}:{self.line}"
        return ": ".join(part for part in (where, self.path, self.message) if part)


class CurriculumError(ValueError):
    """A curriculum that cannot be used; ``problems`` lists everything found, not just the first."""

    def __init__(self, problems: list[Problem]) -> None:
        super().__init__("\n".join(str(problem) for problem in problems))
        self.problems = problems


class EnvConfig(BaseModel):
    """The environment of one stage; ``env_kwargs`` is what ``LanroEnv(task, **kwargs)`` takes."""

    model_config = ConfigDict(extra="forbid")

    objects: int = Field(2, ge=2, le=3)
    mode: Literal["color", "shape", "color_shape"] = "color"
    correction_rate: float = Field(0.0, ge=0.0, le=1.0)
    negations: bool = False
    max_delay: int = Field(0, ge=0, le=20)
    rare_words: bool = False
    kinds: list[KindName] | None = None
    """``None`` allows every kind of correction."""
    max_episode_steps: int | None = Field(None, ge=1)
    """``None`` lets the environment choose: longer episodes when corrections give time to recover."""
    random_start: float = Field(0.0, ge=0.0, le=1.0)
    """Share of training episodes that start with the hand at a random point near the table instead of
    the neutral pose; evaluation always starts from the neutral pose."""

    @field_validator("kinds")
    @classmethod
    def _distinct_kinds(cls, kinds: list[KindName] | None) -> list[KindName] | None:
        if kinds is not None:
            if not kinds:
                raise ValueError("kinds must name at least one kind; leave it out to allow all kinds")
            repeated = sorted({kind for kind in kinds if kinds.count(kind) > 1})
            if repeated:
                raise ValueError(f"kinds names {', '.join(repeated)} more than once")
        return kinds

    @model_validator(mode="after")
    def _instructor_accepts(self) -> EnvConfig:
        # The instructor has checks across fields (common ground needs rare words); running them here
        # reports them with the stage's location instead of as a crash when training starts.
        InstructorSettings(
            correction_rate=self.correction_rate,
            negations=self.negations,
            max_delay=self.max_delay,
            rare_words=self.rare_words,
            kinds=tuple(Kind) if self.kinds is None else tuple(Kind(kind) for kind in self.kinds),
        )
        return self

    def env_kwargs(self) -> dict[str, Any]:
        return {key: value for key, value in self.model_dump().items() if value is not None}


class Budget(BaseModel):
    model_config = ConfigDict(extra="forbid")

    steps: int = Field(gt=0)
    """Environment steps, summed over the parallel environments."""


class Promote(BaseModel):
    """When the agent has mastered a stage: the success rate on the episodes of its last ``patience``
    evaluations, pooled, is at least ``success``. Pooling judges a rule on patience x episodes fresh episodes
    at once, so one lucky evaluation neither ends a stage nor, with ``statistic: lower_bound``, does a
    rate that the pooled episodes cannot tell apart from a lower one."""

    model_config = ConfigDict(extra="forbid")

    success: float = Field(ge=0.0, le=1.0)
    on: Literal["overall", "corrected"] = "overall"
    """``corrected``: the success rate of episodes in which the instructor spoke a correction."""
    patience: int = Field(1, ge=1)
    statistic: Literal["mean", "lower_bound"] = "mean"
    """``mean``: the pooled success rate; ``lower_bound``: the lower end of its 95% Wilson interval."""

    @field_validator("on", mode="before")
    @classmethod
    def _renamed(cls, on: Any) -> Any:
        if on == "corrections":
            warnings.warn(
                "promote.on: 'corrections' is deprecated and read as 'corrected' (the success of episodes in which "
                "a correction was spoken); write 'on: corrected'",
                FutureWarning,
                stacklevel=2,
            )
            return "corrected"
        return on


class Stage(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str = Field(pattern=NAME_PATTERN)
    env: EnvConfig = Field(default_factory=EnvConfig)
    budget: Budget
    promote: Promote | None = None
    """``None``: the stage runs its whole budget."""
    on_budget: Literal["advance", "stop"] = "advance"
    """What to do when the budget runs out before promotion: go on regardless, or end the curriculum."""

    @field_validator("promote")
    @classmethod
    def _corrections_exist(cls, promote: Promote | None, info: ValidationInfo) -> Promote | None:
        env = info.data.get("env")  # absent when the env itself failed validation
        if promote is not None and promote.on == "corrected" and env is not None and env.correction_rate == 0:
            raise ValueError(
                "promote on 'corrected' needs env.correction_rate > 0: without corrections there is no "
                "success rate on corrections to measure"
            )
        return promote


class EvalConfig(BaseModel):
    """Evaluations during a stage: they drive promotion and pick ``best``, each on fresh episodes."""

    model_config = ConfigDict(extra="forbid")

    every: int = Field(10_000, gt=0)
    """Environment steps between evaluations."""
    episodes: int = Field(100, gt=0)


class HeldOutConfig(BaseModel):
    """The held-out test episodes on which each stage's ``last`` and ``best`` agents are measured."""

    model_config = ConfigDict(extra="forbid")

    episodes: int = Field(500, gt=0)


class _AgentBase(BaseModel):
    """What ``AgentConfig`` adds to the fields it copies from ``SACSettings``."""

    model_config = ConfigDict(extra="forbid")

    @model_validator(mode="after")
    def _settings_accept(self) -> _AgentBase:
        self.settings()  # SACSettings checks its ranges; its ValueError becomes a located problem
        return self

    def settings(self) -> SACSettings:
        return SACSettings(**self.model_dump())


_SAC_TYPES = typing.get_type_hints(SACSettings)
AgentConfig = create_model(
    "AgentConfig",
    __base__=_AgentBase,
    __module__=__name__,
    __doc__="The agent's settings, one optional key per ``SACSettings`` field: generated from the dataclass "
    "so that a new agent setting can be set from a curriculum without touching this module.",
    **{field.name: (_SAC_TYPES[field.name], field.default) for field in dataclasses.fields(SACSettings)},
)


class Curriculum(BaseModel):
    """A validated training plan. Build one with ``load_curriculum`` to get located error messages."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(pattern=NAME_PATTERN)
    task: TaskName
    seed: int = Field(0, ge=0, lt=FIELD)
    envs: int = Field(2, ge=1, le=64)
    """Parallel environments collecting experience."""
    learning_starts: int = Field(1000, ge=0)
    """Environment steps collected, by the untrained policy, before the first update."""
    agent: AgentConfig = Field(default_factory=AgentConfig)
    eval: EvalConfig = Field(default_factory=EvalConfig)
    test: HeldOutConfig = Field(default_factory=HeldOutConfig)
    stages: list[Stage]

    @field_validator("stages")
    @classmethod
    def _stages_distinct(cls, stages: list[Stage]) -> list[Stage]:
        if not stages:
            raise ValueError("a curriculum needs at least one stage")
        first: dict[str, int] = {}
        for index, stage in enumerate(stages):
            if stage.name in first:
                raise ValueError(
                    f"stages[{first[stage.name]}] and stages[{index}] are both named {stage.name!r}; "
                    "each stage needs its own name, as it gets its own folder"
                )
            first[stage.name] = index
        return stages

    @property
    def max_objects(self) -> int:
        """The most objects any stage uses: the observation must have room for them from the start."""
        return max(stage.env.objects for stage in self.stages)

    @property
    def total_steps(self) -> int:
        return sum(stage.budget.steps for stage in self.stages)

    def to_yaml(self) -> str:
        """The resolved plan (``extends`` applied, defaults filled in), itself a loadable curriculum."""
        return yaml.safe_dump(self.model_dump(mode="json"), sort_keys=False)

    def quick(self) -> Curriculum:
        """A copy small enough to run end to end in a minute or two on two cores, to try a file out."""
        data = self.model_dump()
        data["name"] += "-quick"
        for stage in data["stages"]:
            stage["budget"]["steps"] = min(stage["budget"]["steps"], 1500)
        data["eval"]["every"] = min(data["eval"]["every"], 500)
        data["eval"]["episodes"] = min(data["eval"]["episodes"], 5)
        data["test"]["episodes"] = min(data["test"]["episodes"], QUICK_TEST_EPISODES)
        data["learning_starts"] = min(data["learning_starts"], 256)
        data["agent"]["buffer_size"] = min(data["agent"]["buffer_size"], 100_000)
        return _validate(data, {}, "<quick>")

    def with_overrides(self, seed: int | None = None, envs: int | None = None) -> Curriculum:
        """A copy with the command line's settings, checked like the file's."""
        data = self.model_dump()
        overrides = {"seed": seed, "envs": envs}
        data.update({key: value for key, value in overrides.items() if value is not None})
        return _validate(data, {}, "<command line>")


_BUILTIN_FILE = "<built-in quick curriculum>"
_BUILTIN_YAML = """\
# The paper's progression on reach: plain instructions, then corrections, then negations among three objects.
name: reach-basics
task: reach
envs: 2
learning_starts: 256
agent:
  architecture: objects
eval:
  every: 500
  episodes: 5
stages:
  - name: single
    env: {objects: 2, mode: color}
    budget: {steps: 1500}
    promote: {success: 0.9, on: overall}
  - name: corrections
    env: {objects: 2, mode: color, correction_rate: 0.5, max_delay: 5}
    budget: {steps: 1500}
    promote: {success: 0.7, on: corrected}
  - name: negations
    env: {objects: 3, mode: color_shape, correction_rate: 0.5, negations: true, max_delay: 5}
    budget: {steps: 1500}
"""


def builtin_curriculum() -> Curriculum:
    """The curriculum ``lanro train --quick`` runs without a file, checked exactly as a file would be."""
    data, marks = _parse(_BUILTIN_YAML, _BUILTIN_FILE)
    return _validate(data, marks, _BUILTIN_FILE)


def load_curriculum(path: str | Path) -> Curriculum:
    """Reads, merges and validates a curriculum; raises ``CurriculumError`` listing every problem."""
    path = Path(path)
    data, marks = _resolve(path, (path.resolve(),), None)
    return _validate(data, marks, path)


def diff_curricula(old: Curriculum, new: Curriculum, old_label: str, new_label: str) -> str:
    """What changed between two resolved plans, e.g. a run's saved plan and its edited file; empty if equal."""
    lines = difflib.unified_diff(
        old.to_yaml().splitlines(keepends=True),
        new.to_yaml().splitlines(keepends=True),
        fromfile=old_label,
        tofile=new_label,
    )
    return "".join(lines)


# -- reading -----------------------------------------------------------------------------------------------


class _Mark(NamedTuple):
    file: Path | str
    line: int | None


_Marks = dict[KeyPath, _Mark]
_BOOL_TAG = "tag:yaml.org,2002:bool"


class _Loader(yaml.SafeLoader):
    """Safe loading with YAML 1.2 booleans (only true/false). PyYAML follows YAML 1.1, where the key ``on``
    of ``promote`` would load as the boolean True."""

    yaml_implicit_resolvers = {
        first: [(tag, regexp) for tag, regexp in resolvers if tag != _BOOL_TAG]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
    }


_Loader.add_implicit_resolver(_BOOL_TAG, re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF"))


def _resolve(path: Path, chain: tuple[Path, ...], named_at: _Mark | None) -> tuple[dict[str, Any], _Marks]:
    """``path`` merged onto the files it extends. ``chain`` holds the files being loaded, to find cycles;
    ``named_at`` is the ``extends`` that named ``path``, where a file that cannot be read is reported."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeError) as error:
        reason = "no such file" if isinstance(error, FileNotFoundError) else f"cannot read it: {error}"
        if named_at is None:
            raise CurriculumError([Problem(path, None, "", reason)]) from None
        raise CurriculumError([Problem(named_at.file, named_at.line, "extends", f"{path}: {reason}")]) from None
    data, marks = _parse(text, path)
    if "extends" not in data:
        return data, marks
    parent_name = data.pop("extends")
    here = marks.pop(("extends",), _Mark(path, None))
    if not isinstance(parent_name, str) or not parent_name:
        raise CurriculumError([Problem(here.file, here.line, "extends", "must name the YAML file to build on")])
    parent = path.parent / parent_name
    if parent.resolve() in chain:
        cycle = " -> ".join(str(file) for file in (*chain, parent.resolve()))
        message = f"extending {parent} makes a cycle: {cycle}"
        raise CurriculumError([Problem(here.file, here.line, "extends", message)])
    parent_data, parent_marks = _resolve(parent, (*chain, parent.resolve()), here)
    kept = {key: mark for key, mark in parent_marks.items() if not _replaced(key, parent_data, data)}
    return _merge(parent_data, data), kept | marks


def _parse(text: str, file: Path | str) -> tuple[dict[str, Any], _Marks]:
    """The data of one YAML document, and the line of every key and list item in it."""
    try:
        data = yaml.load(text, Loader=_Loader)
        node = yaml.compose(text, Loader=_Loader)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        reason = getattr(error, "problem", None) or str(error)
        line = None if mark is None else mark.line + 1
        raise CurriculumError([Problem(file, line, "", f"invalid YAML: {reason}")]) from None
    if not isinstance(data, dict):
        found = "nothing" if data is None else f"a {type(data).__name__}"
        raise CurriculumError([Problem(file, None, "", f"the top level must be a mapping of keys, found {found}")])
    return data, _key_lines(node, file, ())


def _key_lines(node: yaml.Node, file: Path | str, prefix: KeyPath) -> _Marks:
    marks: _Marks = {}
    if isinstance(node, yaml.MappingNode):
        children = [((key.value,), key, value) for key, value in node.value if isinstance(key, yaml.ScalarNode)]
    elif isinstance(node, yaml.SequenceNode):
        children = [((index,), item, item) for index, item in enumerate(node.value)]
    else:
        return marks
    for step, marked, value in children:
        path = prefix + step
        marks[path] = _Mark(file, marked.start_mark.line + 1)
        marks.update(_key_lines(value, file, path))
    return marks


def _merge(parent: Any, child: Any) -> Any:
    if isinstance(parent, dict) and isinstance(child, dict):
        return {**parent, **{key: _merge(parent.get(key), value) for key, value in child.items()}}
    return child


def _replaced(path: KeyPath, parent: Any, child: Any) -> bool:
    """Whether the child replaces the parent's value at ``path`` or above it, so the parent's line for
    ``path`` no longer describes the merged data."""
    for key in path:
        if key not in child:
            return False
        parent, child = parent.get(key), child[key]
        if not (isinstance(parent, dict) and isinstance(child, dict)):
            return True
    return False


# -- validating ---------------------------------------------------------------------------------------------


def _validate(data: dict[str, Any], marks: _Marks, file: Path | str) -> Curriculum:
    try:
        return Curriculum.model_validate(data)
    except ValidationError as error:
        raise CurriculumError([_problem(details, marks, file) for details in error.errors()]) from None


def _problem(details: ErrorDetails, marks: _Marks, file: Path | str) -> Problem:
    loc = tuple(details["loc"])
    # The deepest key of the path that the file has: a missing key is reported at its parent.
    where = next((marks[loc[:end]] for end in range(len(loc), 0, -1) if loc[:end] in marks), _Mark(file, None))
    return Problem(where.file, where.line, _format_path(loc), _message(details))


def _format_path(loc: KeyPath) -> str:
    text = ""
    for key in loc:
        text += f"[{key}]" if isinstance(key, int) else f".{key}" if text else str(key)
    return text


def _message(details: ErrorDetails) -> str:
    kind, loc, value = details["type"], details["loc"], details["input"]
    if kind == "extra_forbidden":
        model = _model_at(loc[:-1])
        names = [] if model is None else list(model.model_fields) + (["extends"] if model is Curriculum else [])
        close = difflib.get_close_matches(str(loc[-1]), names, n=1)
        return f"unknown key {loc[-1]!r}" + (f"; did you mean {close[0]!r}?" if close else "")
    if kind == "missing":
        return "required key is missing"
    if kind == "value_error":
        return str(details["ctx"]["error"])
    if isinstance(value, (str, int, float)):
        return f"{details['msg']}, got {value!r}"
    return details["msg"]


def _model_at(loc: KeyPath) -> type[BaseModel] | None:
    """The model that the data at ``loc`` is validated as, to list the keys it allows."""
    model: type[BaseModel] | None = Curriculum
    for key in loc:
        if isinstance(key, int):  # a list item: the model was already unwrapped from list[...]
            continue
        if model is None or key not in model.model_fields:
            return None
        model = _model_in(model.model_fields[key].annotation)
    return model


def _model_in(annotation: Any) -> type[BaseModel] | None:
    if typing.get_origin(annotation) is None and isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    return next((model for arg in typing.get_args(annotation) if (model := _model_in(arg))), None)
