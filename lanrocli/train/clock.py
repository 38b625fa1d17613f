"""Where a run's time goes: collecting, updating and evaluating, each with the work it did, so that a user
sees which one to make faster (``report.md`` and the end of every stage)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

RATES = ("collection", "updates", "evaluation")
"""The phases whose speed a run reports, in the order reports show them."""


@dataclass
class PhaseClock:
    """Seconds spent in each phase of training and the work done there, summed over every resumed part of
    a run (it is saved in each checkpoint)."""

    collection_s: float = 0.0
    """Acting, waiting for the simulation and storing episodes: all of a training step but its updates."""
    update_s: float = 0.0
    """Sampling (and relabelling) batches and the gradient updates."""
    updates: int = 0
    evaluation_s: float = 0.0
    evaluation_steps: int = 0
    """Environment steps of the evaluations between training steps (not of the tests)."""

    def since(self, earlier: PhaseClock) -> PhaseClock:
        """What this clock counted after ``earlier`` (an earlier reading of it)."""
        return PhaseClock(*(getattr(self, f.name) - getattr(earlier, f.name) for f in dataclasses.fields(self)))

    def rates(self, env_steps: int) -> dict[str, float | None]:
        """Per second of its own phase: environment steps collected, updates, evaluation steps; None for a
        phase that took no time."""

        def per_second(work: float, seconds: float) -> float | None:
            return work / seconds if seconds > 0 else None

        work = (
            (env_steps, self.collection_s),
            (self.updates, self.update_s),
            (self.evaluation_steps, self.evaluation_s),
        )
        return {phase: per_second(done, seconds) for phase, (done, seconds) in zip(RATES, work)}

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None) -> PhaseClock:
        """A saved clock; an empty one for a checkpoint written before clocks were saved."""
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in (data or {}).items() if k in known})
