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

Every state a kill, a full disk or a damaged file can leave continues with one of two commands: a folder
holding no checkpoint yet is started over by either a fresh start or ``--resume``; a damaged newest
checkpoint makes ``--resume`` fall back to the newest whole one, setting the newer ones aside. Each
checkpoint carries copies of ``config.yaml`` and ``metrics.csv`` as they were when it was written, so a
resumed run rewrites both from it, whatever happened to them since.

What the run writes, and where, is :mod:`lanrocli.train.runfolder`'s business.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import torch

from lanrocli.choices import Instruction, Split
from lanrocli.envs.evaluation import EvaluationReport
from lanrocli.envs.figures import Rate, wilson_interval
from lanrocli.train.curriculum import Curriculum, CurriculumError, Promote, Stage, diff_curricula, load_curriculum
from lanrocli.train.runfolder import (
    AGENT_METRICS,
    BEST,
    CONFIG,
    CORRECTION_TEST,
    SPLITS,
    LANGUAGE,
    LAST,
    LATEST,
    METRICS,
    LOCK,
    SET_ASIDE,
    TEST,
    CheckpointError,
    RunError,
    RunLock,
    align_metrics,
    append_metrics,
    best_checkpoint,
    checkpoint_steps,
    clear_leftovers,
    is_leftover,
    publish,
    read_pointer,
    repoint,
    resumable_candidates,
    set_aside,
    stage_folder,
    step_checkpoint,
    truncate_metrics,
    write_json,
    write_report,
    write_text,
)
from lanrocli.train.seeds import evaluation_seed
from lanrocli.train.checkpoint import resolve_checkpoint
from lanrocli.train.tensorboard import TensorBoard
from lanrocli.train.testset import CORRECTION_QUOTA, Measurement, checkpoint_name, correction_test, measure, split_test
from lanrocli.train.trainer import Trainer, TrainSettings

Loaded = TypeVar("Loaded")


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


def _once_per_agent(
    folder: Path, names: list[str], measured: Callable[[Path], Measurement]
) -> dict[str, Measurement]:
    """``measured`` of each pointer of ``names`` in a stage's ``folder``, measured once per agent: ``best``
    taken at the stage's last evaluation is the ``last`` agent (the same step, the same weights), and its
    measurement is the other's, its record under its own checkpoint name."""
    measurements: dict[str, Measurement] = {}
    by_step: dict[str, Measurement] = {}
    for name in names:
        directory = resolve_checkpoint(folder / name)
        step = directory.name.rsplit("-", 1)[-1]
        if step not in by_step:
            by_step[step] = measured(directory)
        found = by_step[step]
        record = {**found.record, "checkpoint": checkpoint_name(directory)}
        measurements[name] = dataclasses.replace(found, record=record)
    return measurements


def _records(measurements: dict[str, Measurement]) -> dict[str, dict[str, Any]]:
    return {name: measurement.record for name, measurement in measurements.items()}


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
        if out.exists() and not out.is_dir():
            raise RunError(f"{out} is a file, not a run folder; choose another folder with --out")
        lock = RunLock(out)
        with _released_on_error(lock):
            entries = [entry for entry in out.iterdir() if entry.name != LOCK]
            if not all(is_leftover(entry) for entry in entries):
                raise RunError(
                    f"{out} is not empty. Continue the run there with --resume, or choose another folder with --out."
                )
            notes = [f"{out} held a run stopped before its first checkpoint: starting it over"] if entries else []
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
        with _released_on_error(lock):
            candidates = resumable_candidates(out)
            if not candidates and not (out / LATEST).exists():
                plan = curriculum or _saved_plan(out)
                notes = [f"{out} has no checkpoint yet (the run stopped before its first one): starting it over"]
                return cls._begin(plan, out, device, observer, lock, notes)
            directory, (trainer, extra), notes = _newest_whole(out, candidates, lambda d: Trainer.load(d, device))
            try:
                saved = _restore_files(out, directory, extra, notes)
                if curriculum is not None:
                    changes = diff_curricula(saved, curriculum, f"{out / CONFIG} (the run's)", "the curriculum given now")
                    if changes:
                        raise RunError(
                            "the curriculum differs from the one this run was started with, so it was not resumed. "
                            "Resume with the same file and options, or start a new run with another --out.\n"
                            + changes
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
        every = self.curriculum.eval.every
        self.complete_tests()
        while not self.state.finished:
            stage = stages[self.state.stage]
            start = self.state.stage_start
            if self.state.evaluations == 0 and self.trainer.progress.env_steps == start:
                self.observer.on_stage_start(self, stage)
            used = self.trainer.progress.env_steps - start
            target = start + min((used // every + 1) * every, stage.budget.steps)
            if not self.trainer.run(target, should_stop, self._on_step):
                self._checkpoint(stage_index=self.state.stage, best=False)
                return False
            self._evaluate(stage)
        return True

    def _on_step(self, trainer: Trainer) -> None:
        figures = {**trainer.last_metrics, "train_success": trainer.train_success}
        self._tensorboard.train(trainer.progress.env_steps, figures)
        self.observer.on_step(self)

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
        self._tensorboard.mark(trainer.progress.env_steps)

    def _test(self, result: StageResult) -> None:
        """The stage's last and best agents on its held-out test episodes, read back from their
        checkpoints; the final agent of the run also with a blank and another object's sentence, and the last
        stage's agents on the correction test, sized like the test (``CorrectionQuota.scaled``), and on each
        generalisation split of the run's holdout, as many episodes as the test."""
        stage = self.curriculum.stages[result.index]
        folder = self.out / stage_folder(result.index, stage.name)
        episodes = self.curriculum.test.episodes
        device = self.trainer.device
        agents = [name for name in (LAST, BEST) if (folder / name).is_file()]
        tested = _once_per_agent(folder, agents, lambda path: measure(path, episodes, device))
        record: dict[str, Any] = _records(tested)
        figures = {name: measurement.report.metrics() for name, measurement in tested.items()}
        if self.state.finished and result is self.state.results[-1]:
            plain = {"correction_rate": 0.0}
            language = {
                shown.value: measure(folder / LAST, episodes, device, plain, instruction=shown) for shown in Instruction
            }
            record[LANGUAGE] = _records(language)
            quota = CORRECTION_QUOTA.scaled(episodes)
            corrections = _once_per_agent(folder, agents, lambda path: correction_test(path, quota, device))
            record[CORRECTION_TEST] = _records(corrections)
            measured = {LANGUAGE: language, CORRECTION_TEST: corrections}
            splits = self.trainer.settings.holdout.splits
            if splits:
                split_tests = {split.value: self._split_test(folder, agents, split) for split in splits}
                record[SPLITS] = {split: _records(by_agent) for split, by_agent in split_tests.items()}
                measured |= {f"{SPLITS}/{split}": by_agent for split, by_agent in split_tests.items()}
            for kind, by_name in measured.items():
                figures |= {f"{kind}/{name}": measurement.report.metrics() for name, measurement in by_name.items()}
        write_json(folder / TEST, record)
        write_report(self.out, self.curriculum, self.state)
        self._tensorboard.test(result.end, figures)

    def _split_test(self, folder: Path, agents: list[str], split: Split) -> dict[str, Measurement]:
        episodes, device = self.curriculum.test.episodes, self.trainer.device
        return _once_per_agent(folder, agents, lambda path: split_test(path, split, episodes, device))

    def complete_tests(self) -> None:
        """Measure stages that ended but were not measured yet: a run killed while testing does it on resume."""
        for result in self.state.results:
            stage = self.curriculum.stages[result.index]
            if not (self.out / stage_folder(result.index, stage.name) / TEST).is_file():
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

    def close(self) -> None:
        self.trainer.close()
        self._tensorboard.close()
        self._lock.release()


def _train_settings(curriculum: Curriculum) -> TrainSettings:
    """The trainer's settings at the start of the curriculum's first stage."""
    return TrainSettings(
        task=curriculum.task,
        env=curriculum.stages[0].env.settings(),
        seed=curriculum.seed,
        envs=curriculum.envs,
        eval_episodes=curriculum.eval.episodes,
        learning_starts=curriculum.learning_starts,
        updates_per_step=curriculum.updates_per_step,
        buffer=curriculum.buffer.settings(),
        object_slots=curriculum.max_objects,
        max_corrections=curriculum.max_corrections,
        stage=0,
        holdout=curriculum.holdout.settings(),
    )


def _saved_plan(out: Path) -> Curriculum:
    """The curriculum a run without a checkpoint was started with, to start it over."""
    try:
        return load_curriculum(out / CONFIG)
    except (CurriculumError, OSError):
        raise RunError(
            f"{out} holds no checkpoint and no readable {CONFIG}: start it again with the curriculum file, "
            f"'lanro train CURRICULUM --out {out}' (what is there is replaced, as nothing was trained yet)"
        ) from None


def _newest_whole(out: Path, candidates: list[Path], load: Callable[[Path], Loaded]) -> tuple[Path, Loaded, list[str]]:
    """The checkpoint to resume from, loaded: the one ``latest`` names when it is whole, else the newest
    whole one, whose checkpoints written later are then set aside. Raises ``RunError`` when none is whole."""
    problems: list[str] = []
    try:
        named = read_pointer(out / LATEST)
        if named.is_dir():
            candidates = [named, *(c for c in candidates if c != named)]
        else:
            problems.append(f"{out / LATEST} names {named.relative_to(out)}, which does not exist")
    except CheckpointError as error:
        problems.append(str(error))
    newest = max((checkpoint_steps(c) or 0 for c in candidates), default=0)
    for directory in candidates:
        try:
            loaded = load(directory)
        except CheckpointError as error:
            problems.append(str(error))
            continue
        notes = [f"damaged: {problem}" for problem in problems]
        steps = checkpoint_steps(directory) or 0
        if problems:
            notes.append(
                f"resuming from the newest whole checkpoint, {directory.parent.name}/{directory.name}: "
                f"{newest - steps:,} environment steps will be trained again"
            )
        moved = set_aside(out, steps)
        if moved:
            notes.append(f"{len(moved)} checkpoint(s) written after it were moved to {out / SET_ASIDE}; delete them when done")
        if problems or moved:
            repoint(out, directory)
        return directory, loaded, notes
    listed = "\n".join(f"  {problem}" for problem in problems)
    raise RunError(
        f"{out} holds no whole checkpoint to resume from:\n{listed}\n"
        f"Start a new run with another --out, or delete {out} and start again."
    )


@contextmanager
def _released_on_error(lock: RunLock) -> Iterator[None]:
    """Hold ``lock`` beyond the block only if it succeeds: a run that fails to open lets the folder go."""
    try:
        yield
    except BaseException:
        lock.release()
        raise


def _restore_files(out: Path, directory: Path, extra: dict[str, Any], notes: list[str]) -> Curriculum:
    """Rewrite ``config.yaml`` and ``metrics.csv`` as the checkpoint at ``directory`` saw them (older
    checkpoints hold no copies: their metrics are cut back to the checkpoint's steps), and return the run's
    curriculum."""
    copies = extra.get("files", {})
    if CONFIG in copies:
        config = out / CONFIG
        current = config.read_text() if config.is_file() else None
        if current != copies[CONFIG]:
            notes.append(f"{config} was {'changed' if current is not None else 'missing'}: restored from the checkpoint")
            write_text(config, copies[CONFIG])
    if METRICS in copies:
        write_text(out / METRICS, copies[METRICS])
    else:
        truncate_metrics(out / METRICS, checkpoint_steps(directory) or 0)
    gained = align_metrics(out / METRICS)
    if gained:
        notes.append(
            f"{out / METRICS} was written by an older version: rewritten with {len(gained)} new column(s) "
            f"({', '.join(gained)}), empty in its earlier rows"
        )
    try:
        return load_curriculum(out / CONFIG)
    except (CurriculumError, OSError) as error:
        raise RunError(f"{out} holds no readable {CONFIG} and its checkpoint no copy of it: {error}") from None
