"""What the process that runs a sweep and its trials tell each other: the job a trial is given, the progress
it reports, the stop request it watches, and the observer that shows the sweep. Plain data only, so the
sweep's display needs neither torch nor Ray.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

PENDING = "pending"
RUNNING = "running"
FINISHED = "finished"
STOPPED = "stopped"
FAILED = "failed"
ENDED_BEFORE = "ended before"
"""A trial whose run had ended when the sweep was resumed, left alone."""
NOT_STARTED = "not started"
"""A trial still waiting for its turn when the sweep was stopped."""


@dataclass(frozen=True)
class TrialJob:
    """Everything a trial needs, sent to the Ray worker that runs it."""

    name: str
    out: str
    """The trial's run folder, absolute: every node of a cluster must see it at this path."""
    curriculum: str
    """The trial's resolved curriculum (``Curriculum.to_yaml``), validated before the sweep started."""
    device: str
    stop_file: str


@dataclass(frozen=True)
class TrialProgress:
    """One trial's state as the sweep shows it; each report from a trial is one of these."""

    trial: str
    status: str = PENDING
    stage: str = ""
    """``2/3 corrections``"""
    steps: int = 0
    rate: float | None = None
    """Environment steps per second lately."""
    evaluation: str = ""
    """The last evaluation, in words."""
    line: str = ""
    """What just happened, for a log (an evaluation, a stage's end); empty for a plain progress report."""

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrialProgress:
        return cls(**{f.name: data[f.name] for f in dataclasses.fields(cls) if f.name in data})


class SweepObserver:
    """Shows a sweep while it runs; every method may be left out."""

    def update(self, progress: TrialProgress) -> None: ...

    def note(self, message: str) -> None: ...


class StopFile:
    """A stop request that every trial sees: a file in the sweep folder, which a trial checks at most every
    ``interval`` seconds, so watching costs nothing next to a training step."""

    def __init__(self, path: Path, interval: float = 0.5) -> None:
        self.path = path
        self.interval = interval
        self._next = 0.0
        self._seen = False

    def requested(self) -> bool:
        now = time.monotonic()
        if not self._seen and now >= self._next:
            self._next = now + self.interval
            self._seen = self.path.exists()
        return self._seen
