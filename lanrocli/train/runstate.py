"""Where a run is in its curriculum, saved in every checkpoint, and the promotion rule that moves it on."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from lanrocli.config.sections import Promote, Stage
from lanrocli.evaluation.evaluate import EvaluationReport
from lanrocli.evaluation.metrics import Rate, wilson_interval
from lanrocli.train.clock import PhaseClock


@dataclass
class StageResult:
    """How a finished stage went; the rows of ``report.md``."""

    index: int
    name: str
    start: int
    end: int
    ended: str
    """``promoted`` when the rule held, ``budget`` when the budget ran out first."""
    evaluations: int
    rule_value: float | None
    """What the promotion rule saw at the stage's last evaluation (pooled); None without a rule."""
    wall_time: float
    clock: dict[str, Any] | None = None
    """The run's ``PhaseClock`` at the stage's end (not kept by runs written before it was)."""
    test_seconds: float | None = None
    """How long the stage's tests took, once they have run."""

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> StageResult:
        return cls(**{f.name: data.get(f.name) for f in dataclasses.fields(cls)})


@dataclass
class RunState:
    """Where the run is in its curriculum; saved in every checkpoint beside the trainer's own state."""

    stage: int = 0
    stage_start: int = 0
    evaluations: int = 0
    """Evaluations so far in the current stage."""
    window: list[tuple[int, int]] = field(default_factory=list)
    """(successes, episodes) on what the rule watches, for the stage's last ``patience`` evaluations."""
    best: float | None = None
    """Best success so far in this stage on one evaluation, on what its rule watches (overall without a
    rule); -1 while no evaluation had such episodes."""
    finished: bool = False
    stopped_early: bool = False
    """The run ended at a stage whose budget ran out with ``on_budget: stop``."""
    results: list[StageResult] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def begin(self, stage: int, env_steps: int) -> None:
        """Move on to ``stage``, which starts at ``env_steps`` with no evaluation, rule window or best yet."""
        self.stage, self.stage_start, self.evaluations, self.window, self.best = stage, env_steps, 0, [], None

    def seconds(self, result: StageResult) -> dict[str, float] | None:
        """The seconds of ``result``'s stage spent collecting, updating, evaluating, testing, and on the rest
        (checkpoints, starting environments), with their ``total``: the stage's own wall time and its tests.
        None where its clock or its tests' time was not kept."""
        position = self.results.index(result)
        previous = self.results[position - 1] if position > 0 else None
        if result.clock is None or result.test_seconds is None:
            return None
        if previous is not None and (previous.clock is None or previous.test_seconds is None):
            return None
        spent = PhaseClock.from_dict(result.clock).since(PhaseClock.from_dict(previous.clock if previous else {}))
        # a stage's wall time counts from the previous stage's end, whose tests came first
        before = previous.wall_time + previous.test_seconds if previous else 0.0  # type: ignore[operator]
        total = result.wall_time - before + result.test_seconds
        parts = {
            "collection": spent.collection_s,
            "updates": spent.update_s,
            "evaluation": spent.evaluation_s,
            "tests": result.test_seconds,
        }
        return {**parts, "rest": total - sum(parts.values()), "total": total}

    def shares(self, result: StageResult) -> dict[str, float] | None:
        """The share of ``result``'s stage's own time spent in each phase of :meth:`seconds`."""
        seconds = self.seconds(result)
        if seconds is None or seconds["total"] <= 0:
            return None
        total = seconds.pop("total")
        return {name: value / total for name, value in seconds.items()}

    def rates(self, result: StageResult) -> dict[str, float | None] | None:
        """Steps or updates per second of each phase during ``result``'s stage (``PhaseClock.rates``); None
        where the clock was not kept at its end or the previous stage's."""
        position = self.results.index(result)
        previous = self.results[position - 1].clock if position > 0 else {}
        if result.clock is None or previous is None:
            return None
        spent = PhaseClock.from_dict(result.clock).since(PhaseClock.from_dict(previous))
        return spent.rates(result.end - result.start)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunState:
        known = {f.name for f in dataclasses.fields(cls)}
        results = [StageResult.from_dict(r) for r in data.get("results", [])]
        window = [(int(k), int(n)) for k, n in data.get("window", [])]
        return cls(**{**{k: v for k, v in data.items() if k in known}, "results": results, "window": window})


def watched(stage: Stage, report: EvaluationReport) -> Rate:
    """The episodes the stage's rule watches (all of them without a rule)."""
    return report.corrected if stage.promote is not None and stage.promote.on == "corrected" else report.overall


def pooled_rule(promote: Promote, window: list[tuple[int, int]]) -> tuple[float | None, bool]:
    """The rule's value on the pooled episodes of ``window`` and whether it holds: only once ``patience``
    evaluations are pooled, so a stage is never promoted on fewer episodes than its rule asks for."""
    successes, episodes = sum(k for k, _ in window), sum(n for _, n in window)
    if episodes == 0:
        return None, False
    value = successes / episodes if promote.statistic == "mean" else wilson_interval(successes, episodes)[0]
    return value, len(window) >= promote.patience and value >= promote.success
