"""A run's progress in words, one line at a time: what ``lanro train`` prints and what a sweep's trials report."""

from __future__ import annotations

from typing import Any

from lanrocli.config.sections import Stage
from lanrocli.train.runstate import StageResult

RATE_WINDOW = 10.0
"""Seconds over which environment steps per second are measured."""


def rule_text(stage: Stage) -> str:
    if stage.promote is None:
        return "runs its whole budget"
    return f"promote at {stage.promote.described()}"


def percent(value: Any) -> str:
    return "-" if value in ("", None) else f"{100 * float(value):.0f}%"


def evaluation_summary(row: dict[str, Any]) -> str:
    """An evaluation's row of ``metrics.csv`` in words: ``success 88%, corrected 70% of 20``."""
    corrected = f"corrected {percent(row['corrected_success'])} of {row['corrected_episodes']}"
    return f"success {percent(row['success'])}, {corrected}"


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
