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

from lanrocli.train.stop import StopRequest
from lanrocli.train.pipeline import CurriculumRun, RunObserver
from lanrocli.train.runstate import StageResult
from lanrocli.config.sections import Stage

__all__ = ["StopRequest", "TrainingDisplay"]

PLAIN_INTERVAL = 60.0
"""Seconds between progress lines when the output is not a terminal."""

RATE_WINDOW = 10.0
"""Seconds over which environment steps per second are measured."""


def _rule(stage: Stage) -> str:
    if stage.promote is None:
        return "runs its whole budget"
    return f"promote at {stage.promote.described()}"


def _percent(value: Any) -> str:
    return "-" if value in ("", None) else f"{100 * float(value):.0f}%"


def evaluation_summary(row: dict[str, Any]) -> str:
    """An evaluation's row of ``metrics.csv`` in words: ``success 88%, corrected 70% of 20``."""
    return f"success {_percent(row['success'])}, corrected {_percent(row['corrected_success'])} of {row['corrected_episodes']}"


def stage_end_line(result: StageResult, rates: dict[str, float | None] | None = None) -> str:
    """The line a stage's end prints; with its ``rates`` (``RunState.rates``), where the time went."""
    how = "promoted" if result.ended == "promoted" else "budget spent"
    line = f"stage {result.index + 1} {result.name} ended ({how}) after {result.end - result.start:,} steps"
    if rates:
        units = {"collection": "steps/s collecting", "updates": "updates/s", "evaluation": "steps/s evaluating"}
        line += "; " + ", ".join(f"{value:,.0f} {units[phase]}" for phase, value in rates.items() if value is not None)
    if result.test_seconds is not None:
        line += f"; tests {result.test_seconds / 60:.1f} min"
    return line


class StepRate:
    """Environment steps per second over the last ``RATE_WINDOW`` seconds."""

    def __init__(self) -> None:
        self._samples: list[tuple[float, int]] = []

    def clear(self) -> None:
        self._samples.clear()

    def last_sample(self) -> float | None:
        """When the last sample was taken (``time.monotonic``), or None before the first."""
        return self._samples[-1][0] if self._samples else None

    def add(self, now: float, steps: int) -> float | None:
        """Record ``steps`` at ``now``; the rate over the window, or None while it spans no time."""
        self._samples.append((now, steps))
        while now - self._samples[0][0] > RATE_WINDOW:
            self._samples.pop(0)
        (t0, s0), (t1, s1) = self._samples[0], self._samples[-1]
        return (s1 - s0) / (t1 - t0) if t1 > t0 else None


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
        header = f"stage {index + 1}/{len(run.curriculum.stages)} {stage.name}: {stage.budget.steps:,} steps, {_rule(stage)}"
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
