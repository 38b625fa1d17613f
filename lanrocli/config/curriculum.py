"""Curricula: YAML files of training stages, checked completely before any physics runs.

A file describes the task, the agent's settings, how often to evaluate and a list of stages, each with its
environment, step budget and the rule that promotes the agent to the next stage. Everything wrong with a
file is reported at once, each problem with its file, line and key path (:mod:`lanrocli.config.yamlfile`
reads the files, ``extends`` included; :mod:`lanrocli.config.sections` holds the sections under the top level,
the ``agent``, ``buffer`` and ``env`` sections generated from the dataclasses that own those settings).
"""

from __future__ import annotations

import difflib
from importlib.resources import files
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator

from lanrocli.agent.settings import BufferSettings
from lanrocli.config.overrides import apply_settings
from lanrocli.config.sections import (
    NAME_PATTERN,
    AgentConfig,
    BufferConfig,
    EvalConfig,
    HeldOutConfig,
    HoldoutConfig,
    QuestionsConfig,
    Stage,
)
from lanrocli.config.yamlfile import CurriculumError, KeyProblem, Problem, parse, read, validate
from lanrocli.core.choices import Kind, Split
from lanrocli.core.seeds import FIELD
from lanrocli.envs.scene import check_scenes
from lanrocli.tasks import Task

__all__ = [
    "Curriculum",
    "CurriculumError",
    "Problem",
    "builtin_curriculum",
    "find_curriculum",
    "load_curriculum",
    "packaged_curricula",
]

QUICK_TEST_EPISODES = 40
"""Test episodes per agent and stage of a file scaled down by ``--quick``: enough to see the pipeline work,
in seconds, not to tell one agent from another."""

PACKAGED = "curricula"
"""The package's folder of curricula (package data; the repository's top-level ``curricula/`` links to it)."""
BUILTIN = "quick.yaml"
"""The curriculum ``lanro train --quick`` runs without a file, as written (its budgets are small already),
one of the packaged curricula."""


class Curriculum(BaseModel):
    """A validated training plan. Build one with ``load_curriculum`` to get located error messages."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(pattern=NAME_PATTERN)
    task: Task
    seed: int = Field(0, ge=0, lt=FIELD)
    envs: int = Field(2, ge=1, le=64)
    """Parallel environments collecting experience."""
    learning_starts: int = Field(1000, ge=0)
    """Environment steps collected, by the untrained policy, before the first update."""
    updates_per_step: float = Field(1.0, ge=0)
    """Gradient updates per collected environment step; 0.5 updates every other step."""
    agent: AgentConfig = Field(default_factory=AgentConfig)
    buffer: BufferConfig = Field(default_factory=BufferConfig)
    eval: EvalConfig = Field(default_factory=EvalConfig)
    test: HeldOutConfig = Field(default_factory=HeldOutConfig)
    stages: list[Stage]
    holdout: HoldoutConfig = Field(default_factory=HoldoutConfig)
    questions: QuestionsConfig | None = None
    """The question test of the final agents, where given (docs/questions.md)."""

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

    @field_validator("stages")
    @classmethod
    def _settings_fit_the_task(cls, stages: list[Stage], info: ValidationInfo) -> list[Stage]:
        task = info.data.get("task")  # absent when the task itself failed validation
        if task is None:
            return stages
        for index, stage in enumerate(stages):
            try:
                stage.env.settings().check_task(task)
            except ValueError as error:
                raise ValueError(f"stages[{index}].env: {error}") from None
            if stage.env.questions:
                raise KeyProblem(
                    (index, "env", "questions"),
                    "questions are asked by a rule calibrated on the trained agent's attention, not in training: "
                    "leave them out of the stages and add a top-level `questions:` section (docs/questions.md)",
                )
        return stages

    @field_validator("questions")
    @classmethod
    def _questions_fit_the_plan(cls, questions: QuestionsConfig | None, info: ValidationInfo) -> QuestionsConfig | None:
        """The question test needs an agent that attends to objects and a last stage with room for an answer
        and a correction after it."""
        stages: list[Stage] | None = info.data.get("stages")
        agent: AgentConfig | None = info.data.get("agent")
        if questions is None or not stages or agent is None:
            return questions
        if agent.settings().architecture != "objects":
            raise ValueError(
                "the question test reads the agent's attention over the objects: set agent.architecture: objects"
            )
        last = stages[-1].env.settings()
        try:
            last.replace(**questions.changes())
        except ValueError as error:
            raise ValueError(f"the last stage cannot be tested with questions: {error}") from None
        return questions

    @field_validator("holdout")
    @classmethod
    def _holdout_fits_the_stages(cls, holdout: HoldoutConfig, info: ValidationInfo) -> HoldoutConfig:
        """Every stage keeps a valid goal without the held-out part, and the last stage, where the splits
        are tested, can make each split's episodes."""
        stages: list[Stage] | None = info.data.get("stages")
        if not stages:
            return holdout
        rules = holdout.settings()
        for index, stage in enumerate(stages):
            env = stage.env.settings()
            try:
                check_scenes(env.mode, env.objects, rules)
            except ValueError as error:
                raise KeyProblem(("pairs",), f"{error} (stages[{index}])") from None
        if rules.late_corrections is not None:
            longest = max(stage.env.settings().max_delay for stage in stages)
            if rules.late_corrections[0] <= longest:
                raise KeyProblem(
                    ("late_corrections",),
                    f"the split's first delay {rules.late_corrections[0]} is not longer than training's longest "
                    f"max_delay {longest}; start it at {longest + 1} or more",
                )
        last = stages[-1].env.settings()
        if rules.pairs:
            try:
                check_scenes(last.mode, last.objects, rules, Split.PAIRS)
            except ValueError as error:
                raise KeyProblem(
                    ("pairs",),
                    f"{error}: the last stage, where the split is tested, "
                    "needs a held-out pair it can put on the table",
                ) from None
        if rules.common_ground and not last.rare_words:
            raise KeyProblem(("common_ground",), "the last stage, where the split is tested, needs rare_words: true")
        if rules.common_ground and Kind.COMMON_GROUND not in last.instructor.kinds:
            raise KeyProblem(
                ("common_ground",), "the last stage, where the split is tested, must allow the common_ground kind"
            )
        return holdout

    @property
    def max_objects(self) -> int:
        """The most objects any stage uses: the observation must have room for them from the start."""
        return max(stage.env.objects for stage in self.stages)

    @property
    def max_corrections(self) -> int:
        """The most corrections any stage speaks in one episode: the agent's sentences need room for them
        from the start."""
        return max(stage.env.max_corrections for stage in self.stages)

    @property
    def total_steps(self) -> int:
        return sum(stage.budget.steps for stage in self.stages)

    def evaluation(self, index: int) -> EvalConfig:
        """How stage ``index`` is evaluated: the curriculum's ``eval``, with the stage's own keys in place."""
        return self.stages[index].eval.over(self.eval)

    def buffer_settings(self, index: int) -> BufferSettings:
        """How stage ``index`` samples its batches: the curriculum's ``buffer``, with the stage's own keys in
        place."""
        return self.stages[index].buffer.over(self.buffer.settings())

    def to_yaml(self) -> str:
        """The resolved plan (``extends`` applied, defaults filled in), itself a loadable curriculum."""
        return yaml.safe_dump(self.model_dump(mode="json"), sort_keys=False)

    def quick(self) -> Curriculum:
        """A copy small enough to run end to end in a few minutes on two cores, to try a file out
        (``lanro train FILE --quick``): too small for most curricula to learn anything."""
        data = self.model_dump()
        data["name"] += "-quick"
        for stage in data["stages"]:
            stage["budget"]["steps"] = min(stage["budget"]["steps"], 1500)
            for key, most in (("every", 500), ("episodes", 5)):
                stage["eval"][key] = stage["eval"][key] and min(stage["eval"][key], most)
        data["eval"]["every"] = min(data["eval"]["every"], 500)
        data["eval"]["episodes"] = min(data["eval"]["episodes"], 5)
        data["test"]["episodes"] = min(data["test"]["episodes"], QUICK_TEST_EPISODES)
        data["learning_starts"] = min(data["learning_starts"], 256)
        data["buffer"]["size"] = min(data["buffer"]["size"], 100_000)
        return validate(Curriculum, data, {}, "<quick>")

    def with_settings(self, settings: dict[str, Any], source: str) -> Curriculum:
        """A copy with ``--set`` settings (key path -> value), checked like the file's: each problem is
        located at the setting that caused it, or else named by ``source`` (the curriculum as the command
        line named it) and the settings."""
        changes = [("--set", key, value) for key, value in settings.items()]
        return apply_settings(Curriculum, self.model_dump(mode="json"), changes, source)

    def with_overrides(self, seed: int | None = None, envs: int | None = None) -> Curriculum:
        """A copy with the command line's settings, checked like the file's."""
        data = self.model_dump()
        overrides = {"seed": seed, "envs": envs}
        data.update({key: value for key, value in overrides.items() if value is not None})
        return validate(Curriculum, data, {}, "<command line>")


def packaged_curricula() -> dict[str, Path]:
    """The curricula that ship with the package, by name (``push`` for ``push.yaml``), so that ``lanro train
    push`` runs the same file from any directory and any install. They are read as files, not as resources,
    because ``extends`` names its parent by a path beside the file."""
    folder = Path(str(files("lanrocli") / PACKAGED))
    return {path.stem: path for path in sorted(folder.glob("*.yaml"), key=lambda path: path.stem)}


def find_curriculum(text: str) -> Path:
    """The curriculum file that ``text`` names: a file that exists, as given (it wins over a name); else a
    packaged curriculum by its name, with or without ``.yaml``; else a path that exists, for reading to
    say what it is. Anything else is a ``CurriculumError`` that lists the packaged names."""
    path = Path(text)
    if path.is_file():
        return path
    packaged = packaged_curricula()
    if path.parent == Path(".") and path.name.removesuffix(".yaml") in packaged:
        return packaged[path.name.removesuffix(".yaml")]
    if path.exists():
        return path
    close = difflib.get_close_matches(path.name.removesuffix(".yaml"), packaged, n=1)
    message = f"no such file, nor the name of a packaged curriculum; give a YAML file or one of: {', '.join(packaged)}"
    raise CurriculumError([Problem(text, None, "", message + (f" (did you mean {close[0]}?)" if close else ""))])


def builtin_curriculum() -> Curriculum:
    """The curriculum ``lanro train --quick`` runs without a file, checked exactly as a file would be."""
    resource = packaged_curricula()[Path(BUILTIN).stem]
    data, marks = parse(resource.read_text(encoding="utf-8"), BUILTIN)
    return validate(Curriculum, data, marks, BUILTIN)


def load_curriculum(path: str | Path) -> Curriculum:
    """Reads, merges and validates a curriculum; raises ``CurriculumError`` listing every problem."""
    path = Path(path)
    data, marks = read(path)
    return validate(Curriculum, data, marks, path)


def diff_curricula(old: Curriculum, new: Curriculum, old_label: str, new_label: str) -> str:
    """What changed between two resolved plans, e.g. a run's saved plan and its edited file; empty if equal."""
    lines = difflib.unified_diff(
        old.to_yaml().splitlines(keepends=True),
        new.to_yaml().splitlines(keepends=True),
        fromfile=old_label,
        tofile=new_label,
    )
    return "".join(lines)
