"""One trial of a sweep, in the Ray worker that runs it: its run folder started, or resumed from its own
checkpoints, exactly as ``lanro train`` and ``lanro train --resume`` would, and its progress reported to Ray
Tune. The run folder is the record; Tune only carries progress to the sweep's display.
"""

from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Any

import torch
import yaml
from ray import tune

from lanrocli.config.curriculum import Curriculum
from lanrocli.config.sections import Stage
from lanrocli.config.yamlfile import validate
from lanrocli.sweep.plan import trial_started
from lanrocli.sweep.protocol import FINISHED, RUNNING, STOPPED, StopFile, TrialJob, TrialProgress
from lanrocli.train.pipeline import CurriculumRun, RunObserver
from lanrocli.train.progress import StepRate, evaluation_summary, stage_end_line
from lanrocli.train.runstate import StageResult
from lanrocli.train.writing import lock_holder

REPORT_SECONDS = 5.0
"""Seconds between progress reports; evaluations and stage ends are reported at once."""
LOCK_WAIT_SECONDS = 60.0
"""How long a trial waits for its run folder's lock: the trials of a sweep killed a moment ago take a few
seconds to die with their Ray instance."""


class TuneReporter(RunObserver):
    """Reports a run's progress with ``tune.report``: at every evaluation and stage, and every few seconds."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.evaluation = ""
        self._rate = StepRate()
        self.rate: float | None = None

    def send(self, run: CurriculumRun, status: str = RUNNING, line: str = "") -> None:
        now, steps = time.monotonic(), run.trainer.progress.env_steps
        rate = self._rate.add(now, steps)
        if rate is not None:
            self.rate = rate
        index = min(run.state.stage, len(run.curriculum.stages) - 1)
        stage = f"{index + 1}/{len(run.curriculum.stages)} {run.curriculum.stages[index].name}"
        progress = TrialProgress(self.name, status, stage, steps, self.rate, self.evaluation, line)
        tune.report(progress.to_dict())

    def on_stage_start(self, run: CurriculumRun, stage: Stage) -> None:
        self.send(run, line=f"stage {run.state.stage + 1}/{len(run.curriculum.stages)} {stage.name} starts")

    def on_step(self, run: CurriculumRun) -> None:
        last = self._rate.last_sample()
        if last is None or time.monotonic() - last >= REPORT_SECONDS:
            self.send(run)

    def on_evaluation(self, run: CurriculumRun, row: dict[str, Any]) -> None:
        self.evaluation = evaluation_summary(row)
        self.send(run, line=f"step {row['env_steps']:,}: evaluation {self.evaluation}")

    def on_stage_end(self, run: CurriculumRun, result: StageResult) -> None:
        self.send(run, line=stage_end_line(result, run.state.rates(result)))


def _wait_for_lock(out: Path) -> None:
    deadline = time.monotonic() + LOCK_WAIT_SECONDS
    while lock_holder(out) is not None and time.monotonic() < deadline:
        time.sleep(0.5)


def train_trial(job: TrialJob) -> None:
    """Run the trial ``job`` until its curriculum ends or the sweep asks it to stop (then with a checkpoint).
    A run that has ended already only completes tests a kill interrupted."""
    out = Path(job.out)
    stop = StopFile(Path(job.stop_file))
    reporter = TuneReporter(job.name)
    if stop.requested():
        return
    if job.device == "cpu":
        torch.set_num_threads(1)
        with contextlib.suppress(RuntimeError):  # set once per process: a worker that ran a trial before has
            torch.set_num_interop_threads(1)  # the trials share the cores: updates without a helper thread
    plan = validate(Curriculum, yaml.safe_load(job.curriculum), {}, f"the curriculum of trial {job.name}")
    if trial_started(out):
        _wait_for_lock(out)
        run = CurriculumRun.resume(out, plan, job.device, reporter)
    else:
        run = CurriculumRun.start(plan, out, job.device, reporter)
    try:
        for note in run.notes:
            reporter.send(run, line=f"note: {note}")
        finished = run.run(should_stop=stop.requested)  # a finished run only completes interrupted tests
    finally:
        run.close()
    reporter.send(run, FINISHED if finished else STOPPED, "finished" if finished else "stopped: checkpoint written")
