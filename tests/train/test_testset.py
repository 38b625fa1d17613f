"""The correction test: its own held-out episodes, its settings, its quota, and the same record every time."""

from __future__ import annotations

from pathlib import Path

import pytest

from lanrocli.agent.settings import BufferSettings, SACSettings
from lanrocli.choices import CorrectionForm
from lanrocli.envs.evaluation import EvaluationReport
from lanrocli.envs.figures import ATTENTION, PHASES, PLAIN, EpisodeResult
from lanrocli.envs.settings import EnvSettings
from lanrocli.train.seeds import correction_test_seed, held_out_seed
from lanrocli.train.testset import (
    CORRECTION_QUOTA,
    CORRECTION_TEST_NEGATION_RATE,
    QUOTA_TEST_EPISODES,
    CorrectionQuota,
    correction_test,
    measure,
)
from lanrocli.train.trainer import Trainer, TrainSettings

STAGE = EnvSettings(objects=2, correction_rate=0.5, negations=True, max_episode_steps=8)


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An untrained agent that attends to objects, of a stage with negations: it is what is measured, not how well."""
    settings = TrainSettings(task="reach", env=STAGE, seed=3, stage=1, buffer=BufferSettings(size=10))
    trainer = Trainer(settings, SACSettings(hidden_size=16, obs_size=16, architecture="objects"))
    try:
        return trainer.save(tmp_path_factory.mktemp("run") / "stage-2-negations" / "checkpoint", resumable=False)
    finally:
        trainer.close()


def spoken(forms: list[CorrectionForm | None]) -> EvaluationReport:
    return EvaluationReport([EpisodeResult(True, 5, None, form, -4.0) for form in forms])


def test_the_quota_needs_both_the_corrections_and_where_they_are_on_the_negations() -> None:
    quota = CorrectionQuota(spoken=3, negations=2, episodes=10)
    excuse, negation = CorrectionForm.EXCUSE, CorrectionForm.NEGATION
    assert not quota.met(spoken([excuse, excuse, None, negation]), negations=True)
    assert quota.met(spoken([excuse, excuse, None, negation]), negations=False)
    assert not quota.met(spoken([negation, negation, None]), negations=True)
    assert quota.met(spoken([negation, negation, excuse]), negations=True)


def test_the_quota_is_sized_like_the_test() -> None:
    assert CORRECTION_QUOTA.scaled(QUOTA_TEST_EPISODES) == CORRECTION_QUOTA
    assert CORRECTION_QUOTA == CorrectionQuota(spoken=300, negations=150, episodes=3000)
    assert CORRECTION_QUOTA.scaled(100) == CorrectionQuota(60, 30, 600)
    assert CORRECTION_QUOTA.scaled(2) == CorrectionQuota(2, 1, 12)  # never below one


def test_the_correction_test_has_episodes_and_settings_of_its_own_and_repeats_itself(checkpoint: Path) -> None:
    quota = CorrectionQuota(spoken=50, negations=25, episodes=4)  # an untrained agent is hardly ever corrected
    first = correction_test(checkpoint, quota)
    record = first.record
    assert record["episodes_from"] == {"correction_test": True, "first_seed": correction_test_seed(3, 1)}
    assert first.first_seed not in range(held_out_seed(3, 1), held_out_seed(3, 1) + 10_000)
    assert record["env"]["correction_rate"] == 1.0 and record["env"]["negation_rate"] == CORRECTION_TEST_NEGATION_RATE
    assert record["episodes"] == 4 and record["correction_episodes"] == 4 and not record["quota_met"]
    assert record["quota"] == {"spoken": 50, "negations": 25, "episodes": 4}
    shares = record[ATTENTION]
    assert set(shares) == set(PHASES) and 0.0 <= shares[PLAIN] <= 1.0
    assert correction_test(checkpoint, quota).record == record
    # An option of the caller's wins over the test's own settings; without negations none are asked for.
    plain = correction_test(checkpoint, quota, overrides={"negations": False, "negation_rate": None}).record
    assert plain["env"]["negations"] is False and plain["quota"]["negations"] == 0


def test_the_correction_test_stops_once_its_quota_is_met(checkpoint: Path) -> None:
    # One episode in which no correction is spoken meets a quota of none: the test stops after it.
    record = correction_test(checkpoint, CorrectionQuota(spoken=0, negations=0, episodes=5)).record
    assert record["episodes"] == 1 and record["quota_met"]


def test_the_ordinary_measure_keeps_the_stage_and_its_test_episodes(checkpoint: Path) -> None:
    record = measure(checkpoint, 2).record
    assert record["episodes_from"] == {"test_set": True, "first_seed": held_out_seed(3, 1)}
    assert record["env"]["correction_rate"] == 0.5 and record["env"]["negation_rate"] is None
