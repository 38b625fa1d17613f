"""What ``lanro sweep`` shows while it runs: in a terminal, a live table of the trials (trial, stage,
environment steps, steps per second, last evaluation, status); anywhere else, plain lines, one per event of
a trial (it starts, evaluates, ends a stage, ends) and a progress line per running trial every minute."""

from __future__ import annotations

import shlex
import time
from pathlib import Path

from rich.console import Console
from rich.live import Live
from rich.markup import escape
from rich.table import Table

from lanrocli.sweep.protocol import ENDED_BEFORE, FAILED, FINISHED, RUNNING, STOPPED, SweepObserver, TrialProgress

PLAIN_INTERVAL = 60.0
"""Seconds between a running trial's progress lines when the output is not a terminal."""

STYLES = {RUNNING: "bold", FINISHED: "green", STOPPED: "yellow", FAILED: "red"}


class SweepDisplay(SweepObserver):
    """A live table of the trials (``live=True``) or plain log lines."""

    def __init__(self, console: Console, live: bool, trials: list[TrialProgress]) -> None:
        self.console = console
        self.live = live
        self.rows = {row.trial: row for row in trials}
        self._live: Live | None = None
        self._next_line: dict[str, float] = {}

    @classmethod
    def for_terminal(cls, trials: list[TrialProgress]) -> SweepDisplay:
        console = Console()
        return cls(Console(soft_wrap=not console.is_terminal), console.is_terminal, trials)

    def __enter__(self) -> SweepDisplay:
        if self.live:
            self._live = Live(self._table(), console=self.console, refresh_per_second=2)
            self._live.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._live is not None:
            self._live.update(self._table())
            self._live.stop()
            self._live = None

    def _table(self) -> Table:
        table = Table(title="trials")
        for column in ("trial", "stage", "steps", "steps/s", "last evaluation", "status"):
            table.add_column(column, justify="right" if column in ("steps", "steps/s") else "left")
        for row in self.rows.values():
            rate = "-" if row.rate is None or row.status != RUNNING else f"{row.rate:.0f}"
            table.add_row(
                escape(row.trial),
                escape(row.stage or "-"),
                f"{row.steps:,}",
                rate,
                escape(row.evaluation or "-"),
                f"[{STYLES.get(row.status, 'dim')}]{escape(row.status)}[/]",
            )
        return table

    def update(self, progress: TrialProgress) -> None:
        known = self.rows.get(progress.trial)
        if known is not None and progress.status in (RUNNING, FAILED) and not progress.stage:
            progress = TrialProgress(
                progress.trial, progress.status, known.stage, known.steps, known.rate, known.evaluation, progress.line
            )
        self.rows[progress.trial] = progress
        if self._live is not None:
            self._live.update(self._table())
            return
        now = time.monotonic()
        if progress.line:
            self.console.print(escape(f"[{progress.trial}] {progress.line}"))
            self._next_line[progress.trial] = now + PLAIN_INTERVAL
        elif progress.status == RUNNING and now >= self._next_line.get(progress.trial, 0.0):
            self._next_line[progress.trial] = now + PLAIN_INTERVAL
            rate = "-" if progress.rate is None else f"{progress.rate:.0f}"
            self.console.print(
                escape(
                    f"[{progress.trial}] stage {progress.stage}: {progress.steps:,} steps, {rate} steps/s, "
                    f"last evaluation {progress.evaluation or '-'}"
                )
            )

    def note(self, message: str) -> None:
        (self._live.console if self._live is not None else self.console).print(escape(message))


def resume_command(out: Path) -> str:
    return f"lanro sweep --out {shlex.quote(str(out))} --resume"


def print_outcome(console: Console, statuses: dict[str, str], errors: dict[str, str], out: Path) -> int:
    """What became of the trials, and what to run next; returns the exit code: 0 when every trial has ended,
    1 when one failed, 130 when the others were stopped or never started."""
    for name, error in errors.items():
        console.print(f"[bold red]trial {escape(name)} failed:[/] {escape(error)}", highlight=False)
    done = sum(status in (FINISHED, ENDED_BEFORE) for status in statuses.values())
    console.print(f"{done} of {len(statuses)} trials finished; sweep folder: {out}", highlight=False)
    if done < len(statuses):
        stopped = any(status == STOPPED for status in statuses.values())
        console.print(
            f"{'stopped; ' if stopped else ''}resume with: {resume_command(out)}", markup=False, highlight=False
        )
        return 1 if any(status == FAILED for status in statuses.values()) else 130
    folder = shlex.quote(str(out))
    console.print(f"next: lanro report {folder}   lanro plot {folder} --out curves.png", markup=False, highlight=False)
    return 0
