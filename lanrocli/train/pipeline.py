"""A curriculum run: its stages one after another, evaluated as they go, promoted by their rules.

Within a stage, evaluation happens every ``eval.every`` environment steps counted from the stage's start
and when its budget is spent, each time on fresh episodes. After each evaluation the stage's promotion
rule is checked on the episodes of its last ``patience`` evaluations pooled (their success rate, or the
lower end of its 95% interval); the stage ends when it holds or when the budget is spent, and then the
next stage begins with the same agent and replay buffer, or, for ``on_budget: stop``, the run ends. When a
stage ends, its ``last`` and ``best`` agents are measured on the stage's test episodes, which nothing in
the run selects on; ``report.md`` quotes those figures. The last stage's agents are also measured by the
correction test (:func:`lanrocli.train.testset.correction_test`): correction episodes of their own, until
enough corrections and negations were spoken to judge each kind and form. A checkpoint follows every
evaluation and every interruption, so a resumed run repeats nothing and skips nothing: it ends with the
same stages, step counts and, on CPU, the same numbers as a run that was never stopped.

What the run writes, and where, is :mod:`lanrocli.train.runfolder`'s business; how it continues after a
kill or a damaged checkpoint, :mod:`lanrocli.train.recovery`'s.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from lanrocli.agent.settings import UPDATE_METRICS
from lanrocli.config.curriculum import Curriculum, diff_curricula
from lanrocli.config.sections import Stage
from lanrocli.core.seeds import evaluation_seed
from lanrocli.evaluation.evaluate import EvaluationReport
from lanrocli.train.errors import RunError
from lanrocli.train.recovery import (
    clear_leftovers,
    is_leftover,
    newest_whole,
    released_on_error,
    restore_files,
    resumable_candidates,
    saved_plan,
)
from lanrocli.train.report import write_report
from lanrocli.train.runfolder import (
    CONFIG,
    LATEST,
    METRICS,
    TEST,
    append_metrics,
    best_checkpoint,
    publish,
    stage_folder,
    step_checkpoint,
)
from lanrocli.train.runstate import RunState, StageResult, pooled_rule, watched
from lanrocli.train.tensorboard import TensorBoard
from lanrocli.train.testset import TestsStopped, measure_stage
from lanrocli.train.trainer import Trainer, TrainSettings
from lanrocli.train.writing import LOCK, RunLock, write_json, write_text


class RunObserver:
    """What a run reports while it goes; the CLI draws it, a test records it. Every method may be left out."""

    def on_stage_start(self, run: CurriculumRun, stage: Stage) -> None: ...

    def on_step(self, run: CurriculumRun) -> None: ...

    def on_evaluation(self, run: CurriculumRun, row: dict[str, Any]) -> None: ...

    def on_stage_end(self, run: CurriculumRun, result: StageResult) -> None: ...


class CurriculumRun:
    """Runs a curriculum in its run folder; :meth:`start` a new run or :meth:`resume` one."""

    def __init__(
        self,
        curriculum: Curriculum,
        out: Path,
        trainer: Trainer,
        state: RunState,
        observer: RunObserver | None,
        lock: RunLock,
        notes: list[str] | None = None,
    ) -> None:
        self.curriculum = curriculum
        self.out = out
        self.trainer = trainer
        self.state = state
        self.observer = observer or RunObserver()
        self.notes = notes or []
        """What starting or resuming did that the user should know (a start over, a fallback)."""
        self.workers = 1
        """Processes that measure the stages' agents (1: this one). No figure depends on it, so a run may
        resume with another count: it is the machine's, not the plan's."""
        self._lock = lock
        self._tensorboard = TensorBoard.open(out, trainer.progress.env_steps, curriculum.eval.every)
        if trainer.progress.env_steps == 0:
            self._tensorboard.hyperparameters(curriculum)
        if not state.finished and trainer.settings.stage != state.stage:
            # The checkpoint was written as its stage ended: the next stage starts from here.
            self._enter(state.stage)

    # -- starting and resuming ---------------------------------------------------------------------------

    @classmethod
    def start(
        cls, curriculum: Curriculum, out: Path, device: str | torch.device = "cpu", observer: RunObserver | None = None
    ) -> CurriculumRun:
        """A new run in ``out``, which must not exist, be empty, or hold only what a run killed before its
        first checkpoint left (which is removed): a run with a checkpoint is never overwritten."""
        lock, notes = claim_folder(out)
        with released_on_error(lock):
            return cls._begin(curriculum, out, device, observer, lock, notes)

    @classmethod
    def _begin(
        cls,
        curriculum: Curriculum,
        out: Path,
        device: str | torch.device,
        observer: RunObserver | None,
        lock: RunLock,
        notes: list[str],
    ) -> CurriculumRun:
        clear_leftovers(out)
        write_text(out / CONFIG, curriculum.to_yaml())
        trainer = Trainer(_train_settings(curriculum), curriculum.agent.settings(), device)
        return cls(curriculum, out, trainer, RunState(), observer, lock, notes)

    @classmethod
    def resume(
        cls,
        out: Path,
        curriculum: Curriculum | None = None,
        device: str | torch.device = "cpu",
        observer: RunObserver | None = None,
    ) -> CurriculumRun:
        """The run in ``out`` from its newest whole checkpoint. ``curriculum``, when given, must equal the one
        the run was started with; a run continues with the plan it began with or not at all. A run that
        wrote no checkpoint is started over."""
        if not out.is_dir():
            raise RunError(f"{out} holds no run to resume; start one without --resume")
        lock = RunLock(out)
        with released_on_error(lock):
            candidates = resumable_candidates(out)
            if not candidates and not (out / LATEST).exists():
                plan = curriculum or saved_plan(out)
                notes = [f"{out} has no checkpoint yet (the run stopped before its first one): starting it over"]
                return cls._begin(plan, out, device, observer, lock, notes)
            directory, (trainer, extra), notes = newest_whole(out, candidates, lambda d: Trainer.load(d, device))
            try:
                saved = restore_files(out, directory, extra, notes)
                if curriculum is not None:
                    changes = diff_curricula(
                        saved, curriculum, f"{out / CONFIG} (the run's)", "the curriculum given now"
                    )
                    if changes:
                        raise RunError(
                            "the curriculum differs from the one this run was started with, so it was not resumed. "
                            "Resume with the same file and options, or start a new run with another --out.\n" + changes
                        )
            except BaseException:
                trainer.close()
                raise
            return cls(saved, out, trainer, RunState.from_dict(extra["run"]), observer, lock, notes)

    # -- running -----------------------------------------------------------------------------------------

    def run(self, should_stop: Callable[[], bool] = lambda: False) -> bool:
        """Train until the curriculum is done (True) or ``should_stop`` asks to stop (False, after writing a
        checkpoint to resume from)."""
        stages = self.curriculum.stages
        try:
            self.complete_tests(should_stop)
            while not self.state.finished:
                stage = stages[self.state.stage]
                every = self.curriculum.evaluation(self.state.stage).every
                start = self.state.stage_start
                if self.state.evaluations == 0 and self.trainer.progress.env_steps == start:
                    self.observer.on_stage_start(self, stage)
                used = self.trainer.progress.env_steps - start
                target = start + min((used // every + 1) * every, stage.budget.steps)
                if not self.trainer.run(target, should_stop, self._on_step):
                    self.save_checkpoint()
                    return False
                self._evaluate(stage, should_stop)
        except TestsStopped:
            return False  # the checkpoint before the tests stands; a resumed run tests the stage again
        return True

    def _on_step(self, trainer: Trainer) -> None:
        figures = {**trainer.last_metrics, "train_success": trainer.train_success}
        self._tensorboard.train(trainer.progress.env_steps, figures)
        self.observer.on_step(self)

    def _evaluate(self, stage: Stage, should_stop: Callable[[], bool]) -> None:
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
        self._tensorboard.evaluation(row)
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
                clock=trainer.clock.to_dict(),
            )
            state.results.append(result)
            stop = not holds and stage.on_budget == "stop"
            state.stopped_early = stop
            state.finished = stop or index + 1 == len(self.curriculum.stages)
            if not state.finished:
                state.begin(index + 1, trainer.progress.env_steps)
        self._checkpoint(stage_index=index, best=improved)
        if result is not None:
            self._test(result, should_stop)
            self.observer.on_stage_end(self, result)
            if not state.finished:
                self._enter(state.stage)
        self._tensorboard.mark(trainer.progress.env_steps)

    def _test(self, result: StageResult, should_stop: Callable[[], bool] = lambda: False) -> None:
        """The stage's agents measured (:func:`lanrocli.train.testset.measure_stage`), ``test.json`` and
        ``report.md`` written."""
        stage = self.curriculum.stages[result.index]
        folder = self.out / stage_folder(result.index, stage.name)
        final = self.state.finished and result is self.state.results[-1]
        splits = self.trainer.settings.holdout.splits
        started = time.perf_counter()
        record, figures = measure_stage(
            folder,
            self.curriculum.test.episodes,
            self.trainer.device,
            final,
            splits,
            should_stop,
            self.curriculum.questions,
            self.workers,
        )
        result.test_seconds = round(time.perf_counter() - started, 1)
        write_json(folder / TEST, record)
        write_report(self.out, self.curriculum, self.state)
        self._tensorboard.test(result.end, figures)

    def complete_tests(self, should_stop: Callable[[], bool] = lambda: False) -> None:
        """Measure stages that ended but were not measured yet: a run killed or stopped while testing does it
        on resume. Raises ``TestsStopped`` where ``should_stop`` asks to stop first."""
        for result in self.state.results:
            stage = self.curriculum.stages[result.index]
            if not (self.out / stage_folder(result.index, stage.name) / TEST).is_file():
                self._test(result, should_stop)

    def _enter(self, index: int) -> None:
        evaluation = self.curriculum.evaluation(index)
        self.trainer.enter_stage(
            self.curriculum.stages[index].env.settings(),
            index,
            evaluation.episodes,
            evaluation.correction_rate,
            self.curriculum.buffer_settings(index),
        )

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
        for name in UPDATE_METRICS:
            value = self.trainer.last_metrics.get(name)
            row[name] = "" if value is None else round(value, 5)
        return row

    # -- files ---------------------------------------------------------------------------------------------

    def _checkpoint(self, stage_index: int, best: bool) -> None:
        """A resumable checkpoint in the stage's folder (``last``, and the run's ``latest``), and, when the
        evaluation just made was the stage's best, the agent alone as ``best``."""
        folder = self.out / stage_folder(stage_index, self.curriculum.stages[stage_index].name)
        steps = self.trainer.progress.env_steps
        metrics = self.out / METRICS
        files = {CONFIG: (self.out / CONFIG).read_text(), METRICS: metrics.read_text() if metrics.is_file() else ""}
        extra = {"run": self.state.to_dict(), "files": files}
        last = folder / step_checkpoint(steps)
        if not last.exists():  # an interruption right after an evaluation finds its checkpoint written
            self.trainer.save(last, extra)
        best_agent = self.trainer.save(folder / best_checkpoint(steps), extra, resumable=False) if best else None
        publish(self.out, last, best_agent)

    def save_checkpoint(self) -> None:
        """A resumable checkpoint of the run as it stands, in its current stage's folder."""
        self._checkpoint(stage_index=self.state.stage, best=False)

    def close(self) -> None:
        self.trainer.close()
        self._tensorboard.close()
        self._lock.release()


def claim_folder(out: Path) -> tuple[RunLock, list[str]]:
    """The lock on ``out`` for a new run, and what the user should know; ``out`` must not exist, be empty,
    or hold only what a run killed before its first checkpoint left (removed later, by the new run)."""
    if out.exists() and not out.is_dir():
        raise RunError(f"{out} is a file, not a run folder; choose another folder with --out")
    lock = RunLock(out)
    with released_on_error(lock):
        entries = [entry for entry in out.iterdir() if entry.name != LOCK]
        if not all(is_leftover(entry) for entry in entries):
            raise RunError(
                f"{out} is not empty. Continue the run there with --resume, or choose another folder with --out."
            )
    return lock, [f"{out} held a run stopped before its first checkpoint: starting it over"] if entries else []


def _train_settings(curriculum: Curriculum) -> TrainSettings:
    """The trainer's settings at the start of the curriculum's first stage."""
    return TrainSettings(
        task=curriculum.task,
        env=curriculum.stages[0].env.settings(),
        seed=curriculum.seed,
        envs=curriculum.envs,
        eval_episodes=curriculum.evaluation(0).episodes,
        eval_correction_rate=curriculum.evaluation(0).correction_rate,
        learning_starts=curriculum.learning_starts,
        updates_per_step=curriculum.updates_per_step,
        buffer=curriculum.buffer_settings(0),
        object_slots=curriculum.max_objects,
        max_corrections=curriculum.max_corrections,
        stage=0,
        holdout=curriculum.holdout.settings(),
    )
