"""What ``lanro train`` shows while it runs (and, from :mod:`lanrocli.train.stop`, how it stops when asked).

In a terminal: a live progress bar over the current stage's budget with its promotion rule, environment
steps per second, the last evaluation and the time left. Anywhere else (CI, nohup, a cluster job's log) a
live display would fill the log with control codes, so plain lines are printed instead: one per
evaluation, one per stage, and a progress line every minute.
"""

from __future__ import annotations

import time
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from lanrocli.config.sections import Stage
from lanrocli.train.pipeline import CurriculumRun, RunObserver
from lanrocli.train.progress import StepRate, evaluation_summary, rule_text, stage_end_line
from lanrocli.train.runstate import StageResult

PLAIN_INTERVAL = 60.0
"""Seconds between progress lines when the output is not a terminal."""


class TrainingDisplay(RunObserver):
    """Draws a run's progress live (``live=True``) or as plain periodic lines."""

    def __init__(self, console: Console, live: bool) -> None:
        self.console = console
        self.live = live
        self._progress: Progress | None = None
        self._task: Any = None
        self._last_eval = "no evaluation yet"
        self._rate = StepRate()
        self._next_line = 0.0

    @classmethod
    def for_terminal(cls) -> TrainingDisplay:
        console = Console()
        # A log file has no width: long lines stay whole, so commands printed in them can be copied.
        return cls(Console(soft_wrap=not console.is_terminal), live=console.is_terminal)

    def __enter__(self) -> TrainingDisplay:
        if self.live:
            self._progress = Progress(
                TextColumn("[bold]{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.fields[rate]} steps/s"),
                TimeRemainingColumn(),
                TextColumn("{task.fields[evaluation]}"),
                console=self.console,
            )
            self._progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None

    # -- observer --------------------------------------------------------------------------------------------

    def on_stage_start(self, run: CurriculumRun, stage: Stage) -> None:
        index = run.state.stage
        budget = f"{stage.budget.steps:,} steps, {rule_text(stage)}"
        header = f"stage {index + 1}/{len(run.curriculum.stages)} {stage.name}: {budget}"
        self._rate.clear()
        if self._progress is not None:
            self._progress.console.print(header)
            if self._task is not None:
                self._progress.remove_task(self._task)
            self._task = self._progress.add_task(
                f"{index + 1}. {stage.name}", total=stage.budget.steps, rate="-", evaluation=self._last_eval
            )
        else:
            self.console.print(header)
            self._next_line = time.monotonic() + PLAIN_INTERVAL

    def on_step(self, run: CurriculumRun) -> None:
        now, last = time.monotonic(), self._rate.last_sample()
        if last is not None and now - last < 0.25:
            return
        steps = run.trainer.progress.env_steps
        per_second = self._rate.add(now, steps)
        rate = "-" if per_second is None else f"{per_second:.0f}"
        done = steps - run.state.stage_start
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, completed=done, rate=rate, evaluation=self._last_eval)
        elif not self.live and now >= self._next_line:
            self._next_line = now + PLAIN_INTERVAL
            stage = run.curriculum.stages[run.state.stage]
            self.console.print(
                escape(f"[{stage.name}] {done:,}/{stage.budget.steps:,} steps, {rate} steps/s, last {self._last_eval}")
            )

    def on_evaluation(self, run: CurriculumRun, row: dict[str, Any]) -> None:
        self._last_eval = f"evaluation: {evaluation_summary(row)}"
        line = escape(f"[{row['stage_name']}] step {row['env_steps']:,}: {self._last_eval}")
        if self._progress is not None:
            self._progress.console.print(line)
        else:
            self.console.print(line)

    def on_stage_end(self, run: CurriculumRun, result: StageResult) -> None:
        console = self._progress.console if self._progress is not None else self.console
        console.print(stage_end_line(result, run.state.rates(result)))
