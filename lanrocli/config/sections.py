"""The sections of a curriculum file under its top level: a stage with its budget and promotion rule, the
evaluation, the test and the holdout; and the ``agent``, ``buffer`` and ``env`` sections, generated from the
dataclasses that own those settings (``SACSettings``, ``BufferSettings``, ``EnvSettings``), so a new setting
of either needs no change here (a sampling setting a stage may change is listed in ``STAGE_BUFFER_KEYS``).
:mod:`lanrocli.config.curriculum` puts them together and checks them against each other. Like it, this loads
neither torch nor pybullet."""

from __future__ import annotations

import dataclasses
import math
import typing
from typing import Any, ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, create_model, field_validator, model_validator

from lanrocli.agent.settings import BufferSettings, SACSettings
from lanrocli.envs.settings import EnvSettings
from lanrocli.language.holdout import Holdout

NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]*$"
"""Curriculum and stage names become folder names: no separators, no leading dot."""


class _Settings(BaseModel):
    """A section generated from a settings dataclass, one optional key per field, checked by the dataclass."""

    model_config = ConfigDict(extra="forbid")
    settings_class: ClassVar[type]

    @model_validator(mode="after")
    def _settings_accept(self) -> _Settings:
        self.settings()
        return self

    def settings(self) -> Any:
        return self.settings_class(**{name: getattr(self, name) for name in type(self).model_fields})


class _KeyByKey(_Settings):
    """A section whose dataclass checks each key alone (the others at their defaults) before all of them
    together, so that a problem with one setting is reported at its own key and line. The environment's
    checks are per setting; the agent's are reported at the section, as some of them name several keys."""

    @field_validator("*")
    @classmethod
    def _key_accepted(cls, value: Any, info: ValidationInfo) -> Any:
        cls.settings_class(**{info.field_name: value})
        return value


def _section(settings_class: type, name: str, base: type[BaseModel], keys: tuple[str, ...] | None = None) -> Any:
    """A model with one optional key per field of ``settings_class``; with ``keys``, per field named there, each
    ``None`` (absent) unless given: what a stage changes of a curriculum's section."""
    hints = typing.get_type_hints(settings_class)
    if keys is None:
        fields = {f.name: (hints[f.name], f.default) for f in dataclasses.fields(settings_class)}
    else:
        fields = {key: (hints[key] | None, None) for key in keys}
    model = create_model(name, __base__=base, __module__=__name__, **fields)  # type: ignore[call-overload]
    model.settings_class = settings_class
    model.__doc__ = f"One optional key per field of ``{settings_class.__name__}``, generated from it."
    return model


AgentConfig = _section(SACSettings, "AgentConfig", _Settings)
BufferConfig = _section(BufferSettings, "BufferConfig", _KeyByKey)
EnvConfig = _section(EnvSettings, "EnvConfig", _KeyByKey)


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

    def described(self) -> str:
        """The rule as ``lanro train`` and ``report.md`` state it: ``corrected >= 0.9, 3 pooled``."""
        statistic = ">=" if self.statistic == "mean" else "lower bound >="
        return f"{self.on} {statistic} {self.success:g}, {self.patience} pooled"


class EvalConfig(BaseModel):
    """Evaluations during a stage: they drive promotion and pick ``best``, each on fresh episodes."""

    model_config = ConfigDict(extra="forbid")

    every: int = Field(10_000, gt=0)
    """Environment steps between evaluations."""
    episodes: int = Field(100, gt=0)
    correction_rate: float | None = Field(None, gt=0.0, le=1.0)
    """Share of the evaluation episodes that are correction episodes in a stage that speaks corrections (a
    stage without them keeps none); ``None``: the stage's own share. A rule ``on: corrected`` is judged on the
    episodes in which a correction was spoken; at 1 an evaluation speaks about twice as many of them as at
    0.5, for the same episodes, so a lucky run of evaluations ends a stage less often. Tests keep the stage's
    share."""

    def described(self) -> str:
        share = self.correction_rate
        where = "" if share is None else f" ({share:.0%} of them correction episodes where a stage speaks corrections)"
        return f"{self.episodes} fresh episodes{where}"


class StageEval(BaseModel):
    """A stage's evaluations where they differ from the curriculum's: each key given replaces the
    curriculum's for this stage alone; an absent or null key keeps it (to judge a stage on its own share of
    correction episodes under a curriculum-wide ``correction_rate``, give that share). So a late stage can be judged
    differently (every evaluation a correction episode, say) and screened with ``--from`` without
    training the earlier stages again, which a change to the curriculum's ``eval`` would alter."""

    model_config = ConfigDict(extra="forbid")

    every: int | None = Field(None, gt=0)
    episodes: int | None = Field(None, gt=0)
    correction_rate: float | None = Field(None, gt=0.0, le=1.0)

    def over(self, base: EvalConfig) -> EvalConfig:
        """``base`` with this stage's keys in place of its own."""
        return base.model_copy(update={key: value for key, value in self.model_dump().items() if value is not None})


STAGE_BUFFER_KEYS = (
    "relabel_ratio",
    "correction_share",
    "hindsight_share",
    "relabel_corrections",
    "relabel_negations",
    "fresh_targets",
    "ground_real",
)
"""The ``BufferSettings`` a stage may change: how batches are drawn and relabelled (``relabel_negations``
for the episodes stored from the stage on, whose sentence pools it fills). The buffer's size is fixed when
the run's buffer is built."""


class _StageBufferBase(BaseModel):
    """A stage's sampling settings where they differ from the curriculum's ``buffer``: each key given
    replaces the curriculum's for this stage alone, so a lever that would slow a curriculum's early stages
    can be screened in its late ones, and with ``--from`` without training the early ones again."""

    model_config = ConfigDict(extra="forbid")
    settings_class: ClassVar[type]

    @field_validator("*")
    @classmethod
    def _key_accepted(cls, value: Any, info: ValidationInfo) -> Any:
        if value is not None:
            cls.settings_class(**{info.field_name: value})
        return value

    def over(self, base: BufferSettings) -> BufferSettings:
        """``base`` with this stage's keys in place of its own."""
        return dataclasses.replace(
            base, **{key: value for key, value in self.model_dump().items() if value is not None}
        )


StageBuffer = _section(BufferSettings, "StageBuffer", _StageBufferBase, STAGE_BUFFER_KEYS)


class Stage(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str = Field(pattern=NAME_PATTERN)
    env: EnvConfig = Field(default_factory=EnvConfig)
    budget: Budget
    promote: Promote | None = None
    """``None``: the stage runs its whole budget."""
    on_budget: Literal["advance", "stop"] = "advance"
    """What to do when the budget runs out before promotion: go on regardless, or end the curriculum."""
    eval: StageEval = Field(default_factory=StageEval)
    """This stage's own evaluation settings, where they differ from the curriculum's ``eval``."""
    buffer: StageBuffer = Field(default_factory=StageBuffer)  # type: ignore[valid-type]
    """This stage's own sampling settings, where they differ from the curriculum's ``buffer``."""

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


class HeldOutConfig(BaseModel):
    """The held-out test episodes on which each stage's ``last`` and ``best`` agents are measured."""

    model_config = ConfigDict(extra="forbid")

    episodes: int = Field(500, gt=0)


class QuestionsConfig(BaseModel):
    """The question test at the end of the run (docs/questions.md): the final agents asking "which one?" by a
    rule calibrated on their attention, and the same agents with questions off, on held-out episodes."""

    model_config = ConfigDict(extra="forbid")

    level: float = Field(0.97, gt=0.0, lt=1.0)
    """The share of scenes on which the rule keeps the object the speaker means."""
    calibration_episodes: int = Field(300, gt=0)
    """Scenes the rule is calibrated on, none of a test's."""
    episodes: int = Field(600, gt=0)
    """Held-out episodes of the test, every one a correction episode of any kind."""
    penalty: float = Field(0.0, ge=0.0)
    """Reward taken off for each question."""
    steps: int = Field(1, ge=0)
    """Steps a question takes, the arm holding still."""

    @model_validator(mode="after")
    def _enough_scenes(self) -> QuestionsConfig:
        needed = math.ceil(1.0 / (1.0 - self.level))
        if self.calibration_episodes < needed:
            raise ValueError(
                f"calibration_episodes ({self.calibration_episodes}) are too few for level {self.level:g}: the rule "
                f"needs at least {needed}, else it asks in every episode"
            )
        if self.steps == 0 and self.penalty == 0.0:
            raise ValueError("a question that takes no step and costs no reward is free: set steps or penalty above 0")
        return self

    def changes(self) -> dict[str, Any]:
        """The last stage's settings as the test changes them: one question, every episode a correction
        episode of any kind (rare words on, so that common-ground episodes exist)."""
        return {
            "correction_rate": 1.0,
            "kinds": None,
            "negation_rate": None,
            "rare_words": True,
            "questions": 1,
            "question_penalty": self.penalty,
            "question_steps": self.steps,
        }


class HoldoutConfig(BaseModel):
    """What training never shows, tested at the end of the last stage: one generalisation split per key
    given (``Holdout`` has the rules; docs/generalisation.md the reasons)."""

    model_config = ConfigDict(extra="forbid")

    pairs: list[str] = []
    """Colour-shape pairs ("red cylinder") never on the table in training; the split's goal is one."""
    correction_words: list[str] = []
    """One shape word per shape, never inside a correction in training; the split's corrections use them."""
    late_corrections: tuple[int, int] | None = None
    """[first, last]: the delays of the split's corrections, all longer than any stage's max_delay."""
    common_ground: list[str] = []
    """Rare colour words never heard in training; the split's common-ground instructions use them."""
    paraphrase: bool = False
    """Test on the paraphrase split: corrections phrased as the grammar never phrases them."""

    @field_validator("*")
    @classmethod
    def _key_accepted(cls, value: Any, info: ValidationInfo) -> Any:
        Holdout.from_dict({info.field_name: value})
        return value

    def settings(self) -> Holdout:
        return Holdout.from_dict(self.model_dump())
