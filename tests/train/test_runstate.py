"""A run's place in its curriculum, and where each stage's time went."""

from __future__ import annotations

import pytest

from lanrocli.train.clock import PhaseClock
from lanrocli.train.runstate import RunState, StageResult


def test_a_stage_time_is_shared_among_its_phases() -> None:
    first_clock = PhaseClock(collection_s=40.0, update_s=30.0, updates=10, evaluation_s=10.0, evaluation_steps=5)
    second_clock = PhaseClock(collection_s=60.0, update_s=60.0, updates=20, evaluation_s=15.0, evaluation_steps=9)
    first = StageResult(0, "a", 0, 10, "promoted", 1, None, 100.0, first_clock.to_dict(), 20.0)
    second = StageResult(1, "b", 10, 20, "budget", 1, None, 180.0, second_clock.to_dict(), 5.0)
    state = RunState(results=[first, second])
    assert state.shares(first) == pytest.approx(
        {"collection": 40 / 120, "updates": 30 / 120, "evaluation": 10 / 120, "tests": 20 / 120, "rest": 20 / 120}
    )
    # the second stage's 180 s include the first stage's 20 s of tests: its own are 60 s and 5 s of tests
    assert state.shares(second) == pytest.approx(
        {"collection": 20 / 65, "updates": 30 / 65, "evaluation": 5 / 65, "tests": 5 / 65, "rest": 5 / 65}
    )
    untimed = StageResult(0, "a", 0, 10, "budget", 1, None, 100.0)  # a stage whose tests have not run
    assert RunState(results=[untimed]).shares(untimed) is None
