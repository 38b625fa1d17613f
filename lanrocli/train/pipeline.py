"""A curriculum run: its stages one after another, evaluated as they go, promoted by their rules.

Within a stage, evaluation happens every ``eval.every`` environment steps counted from the stage's start
and when its budget is spent, each time on fresh episodes. After each evaluation the stage's promotion
rule is checked on the episodes of its last ``patience`` evaluations pooled (their success rate, or the
lower end of its 95% interval); the stage ends when it holds or when the budget is spent, and then the
next stage begins with the same agent and replay buffer, or, for ``on_budget: stop``, the run ends. When a
stage ends, its ``last`` and ``best`` agents are measured on the stage's test episodes, which nothing in
the run selects on; ``report.md`` quotes those figures. A checkpoint follows every evaluation and every
interruption, so a resumed run repeats nothing and skips nothing: it ends with the same stages, step
counts and, on CPU, the same numbers as a run that was never stopped.

What the run writes, and where, is :mod:`lanrocli.train.runfolder`'s business.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from lanrocli.choices import Instruction
from lanrocli.envs.evaluation import EvaluationReport, Rate, wilson_interval
from lanrocli.train.curriculum import Curriculum, Promote, Stage, diff_curricula, load_curriculum
from lanrocli.train.runfolder import (
    AGENT_METRICS,
    BEST,
    CONFIG,
    LANGUAGE,
    LAST,
    LATEST,
    METRICS,
    TEST,
    CheckpointError,
    TensorBoard,
    append_metrics,
    best_checkpoint,
    publish,
    read_pointer,
    stage_folder,
    step_checkpoint,
    truncate_metrics,
    write_json,
    write_report,
)
from lanrocli.train.seeds import evaluation_seed
from lanrocli.train.testset import measure
from lanrocli.train.trainer import Trainer, TrainSettings


class RunError(RuntimeError):
    """A run cannot start or resume as asked (the folder is in use, the curriculum changed, ...)."""


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

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunState:
        known = {f.name for f in dataclasses.fields(cls)}
        results = [StageResult.from_dict(r) for r in data.get("results", [])]
        window = [(int(k), int(n)) for k, n in data.get("window", [])]
        return cls(**{**{k: v for k, v in data.items() if k in known}, "results": results, "window": window})


class RunObserver:
    """What a run reports while it goes; the CLI draws it, a test records it. Every method may be left out."""

    def on_stage_start(self, run: CurriculumRun, stage: Stage) -> None: ...

    def on_step(self, run: CurriculumRun) -> None: ...

    def on_evaluation(self, run: CurriculumRun, row: dict[str, Any]) -> None: ...

    def on_stage_end(self, run: CurriculumRun, result: StageResult) -> None: ...


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


class CurriculumRun:
    """Runs a curriculum in its run folder; :meth:`start` a new run or :meth:`resume` one."""

    def __init__(
        self, curriculum: Curriculum, out: Path, trainer: Trainer, state: RunState, observer: RunObserver | None
    ) -> None:
        self.curriculum = curriculum
        self.out = out
        self.trainer = trainer
        self.state = state
        self.observer = observer or RunObserver()
        self._tensorboard = TensorBoard.open(out, purge_step=trainer.progress.env_steps)
        if not state.finished and trainer.settings.stage != state.stage:
            # The checkpoint was written as its stage ended: the next stage starts from here.
            self._enter(state.stage)

    # -- starting and resuming ---------------------------------------------------------------------------

    @classmethod
    def start(
        cls, curriculum: Curriculum, out: Path, device: str | torch.device = "cpu", observer: RunObserver | None = None
    ) -> CurriculumRun:
        """A new run in ``out``, which must not exist or be empty: a finished run is never overwritten."""
        if out.exists() and (not out.is_dir() or any(out.iterdir())):
            raise RunError(
                f"{out} is not empty. Continue the run there with --resume, or choose another folder with --out."
            )
        out.mkdir(parents=True, exist_ok=True)
        (out / CONFIG).write_text(curriculum.to_yaml())
        first = curriculum.stages[0]
        settings = TrainSettings(
            task=curriculum.task,
            env=first.env.settings(),
            seed=curriculum.seed,
            envs=curriculum.envs,
            eval_episodes=curriculum.eval.episodes,
            learning_starts=curriculum.learning_starts,
            updates_per_step=curriculum.updates_per_step,
            buffer=curriculum.buffer.settings(),
            object_slots=curriculum.max_objects,
            stage=0,
        )
        trainer = Trainer(settings, curriculum.agent.settings(), device)
        return cls(curriculum, out, trainer, RunState(), observer)

    @classmethod
    def resume(
        cls,
        out: Path,
        curriculum: Curriculum | None = None,
        device: str | torch.device = "cpu",
        observer: RunObserver | None = None,
    ) -> CurriculumRun:
        """The run in ``out`` from its latest checkpoint. ``curriculum``, when given, must equal the one the
        run was started with; a run continues with the plan it began with or not at all."""
        config = out / CONFIG
        if not config.is_file():
            raise RunError(f"{out} holds no run to resume ({CONFIG} is missing); start one without --resume")
        saved = load_curriculum(config)
        if curriculum is not None:
            changes = diff_curricula(saved, curriculum, f"{config} (the run's)", "the curriculum given now")
            if changes:
                raise RunError(
                    "the curriculum differs from the one this run was started with, so it was not resumed. "
                    "Resume with the same file and options, or start a new run with another --out.\n" + changes
                )
        try:
            directory = read_pointer(out / LATEST)
        except CheckpointError:
            raise RunError(f"{out} has no checkpoint yet (the run stopped before its first one); start it again") from None
        trainer, extra = Trainer.load(directory, device)
        state = RunState.from_dict(extra["run"])
        truncate_metrics(out / METRICS, trainer.progress.env_steps)
        return cls(saved, out, trainer, state, observer)

    # -- running -----------------------------------------------------------------------------------------

    def run(self, should_stop: Callable[[], bool] = lambda: False) -> bool:
        """Train until the curriculum is done (True) or ``should_stop`` asks to stop (False, after writing a
        checkpoint to resume from)."""
        stages = self.curriculum.stages
        every = self.curriculum.eval.every
        self.complete_tests()
        while not self.state.finished:
            stage = stages[self.state.stage]
            start = self.state.stage_start
            if self.state.evaluations == 0 and self.trainer.progress.env_steps == start:
                self.observer.on_stage_start(self, stage)
            used = self.trainer.progress.env_steps - start
            target = start + min((used // every + 1) * every, stage.budget.steps)
            if not self.trainer.run(target, should_stop, lambda _: self.observer.on_step(self)):
                self._checkpoint(stage_index=self.state.stage, best=False)
                return False
            self._evaluate(stage)
        return True

    def _evaluate(self, stage: Stage) -> None:
        trainer, state = self.trainer, self.state
        index = state.stage
        report = trainer.evaluate(evaluation_seed(self.curriculum.seed, index, state.evaluations))
        state.evaluations += 1
        rate = watched(stage, report)
        value, holds = None, False
        if stage.promote is not None:
            state.window = [*state.window, (rate.successes, rate.episodes)][-stage.promote.patience :]
            value, holds = pooled_rule(stage.promote, state.window)
        # An evaluation without the episodes the rule watches ranks below any with them, so every stage has a best.
        score = rate.success if rate.episodes else -1.0
        improved = state.best is None or score > state.best
        if improved:
            state.best = score
        row = self._row(stage, report, value, holds)
        append_metrics(self.out / METRICS, row)
        self._tensorboard.write(row)
        self.observer.on_evaluation(self, row)

        used = trainer.progress.env_steps - state.stage_start
        result = None
        if holds or used >= stage.budget.steps:
            result = StageResult(
                index=index,
                name=stage.name,
                start=state.stage_start,
                end=trainer.progress.env_steps,
                ended="promoted" if holds else "budget",
                evaluations=state.evaluations,
                rule_value=value,
                wall_time=trainer.wall_time(),
            )
            state.results.append(result)
            stop = not holds and stage.on_budget == "stop"
            state.stopped_early = stop
            state.finished = stop or index + 1 == len(self.curriculum.stages)
            if not state.finished:
                state.stage, state.stage_start, state.evaluations, state.window, state.best = (
                    index + 1, trainer.progress.env_steps, 0, [], None
                )
        self._checkpoint(stage_index=index, best=improved)
        if result is not None:
            self._test(result)
            self.observer.on_stage_end(self, result)
            if not state.finished:
                self._enter(state.stage)

    def _test(self, result: StageResult) -> None:
        """The stage's last and best agents on its held-out test episodes, read back from their
        checkpoints; the final agent of the run also with a blank and another object's sentence."""
        stage = self.curriculum.stages[result.index]
        folder = self.out / stage_folder(result.index, stage)
        episodes = self.curriculum.test.episodes
        device = self.trainer.device
        record = {
            name: measure(folder / name, episodes, device).record for name in (LAST, BEST) if (folder / name).is_file()
        }
        if self.state.finished and result is self.state.results[-1]:
            plain = {"correction_rate": 0.0}
            record[LANGUAGE] = {
                shown.value: measure(folder / LAST, episodes, device, plain, instruction=shown).record
                for shown in Instruction
            }
        write_json(folder / TEST, record)
        write_report(self.out, self.curriculum, self.state)

    def complete_tests(self) -> None:
        """Measure stages that ended but were not measured yet: a run killed while testing does it on resume."""
        for result in self.state.results:
            stage = self.curriculum.stages[result.index]
            if not (self.out / stage_folder(result.index, stage) / TEST).is_file():
                self._test(result)

    def _enter(self, index: int) -> None:
        self.trainer.enter_stage(self.curriculum.stages[index].env.settings(), index)

    def _row(self, stage: Stage, report: EvaluationReport, value: float | None, holds: bool) -> dict[str, Any]:
        progress = self.trainer.progress
        row: dict[str, Any] = {
            "stage": self.state.stage + 1,
            "stage_name": stage.name,
            "env_steps": progress.env_steps,
            "stage_steps": progress.env_steps - self.state.stage_start,
            "wall_time": round(self.trainer.wall_time(), 1),
            **{name: "" if v is None else v for name, v in report.metrics().items()},
            "mean_return": round(report.mean_return, 3),
            "mean_length": round(report.mean_length, 2),
            "train_success": "" if self.trainer.train_success is None else round(self.trainer.train_success, 3),
            "rule_value": "" if value is None else round(value, 4),
            "rule_holds": int(holds),
        }
        for name in AGENT_METRICS:
            value = self.trainer.last_metrics.get(name)
            row[name] = "" if value is None else round(value, 5)
        return row

    # -- files ---------------------------------------------------------------------------------------------

    def _checkpoint(self, stage_index: int, best: bool) -> None:
        """A resumable checkpoint in the stage's folder (``last``, and the run's ``latest``), and, when the
        evaluation just made was the stage's best, the agent alone as ``best``."""
        folder = self.out / stage_folder(stage_index, self.curriculum.stages[stage_index])
        steps = self.trainer.progress.env_steps
        extra = {"run": self.state.to_dict()}
        last = folder / step_checkpoint(steps)
        if not last.exists():  # an interruption right after an evaluation finds its checkpoint written
            self.trainer.save(last, extra)
        best_agent = self.trainer.save(folder / best_checkpoint(steps), extra, resumable=False) if best else None
        publish(self.out, last, best_agent)

    def close(self) -> None:
        self.trainer.close()
        self._tensorboard.close()
