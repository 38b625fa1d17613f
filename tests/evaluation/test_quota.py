"""The correction test's quota: which spoken corrections it waits for, and its size for a run's test."""

from __future__ import annotations

from lanrocli.core.choices import CorrectionForm
from lanrocli.evaluation.evaluate import EvaluationReport
from lanrocli.evaluation.metrics import EpisodeResult
from lanrocli.evaluation.quota import CORRECTION_QUOTA, QUOTA_TEST_EPISODES, CorrectionQuota


def spoken(forms: list[CorrectionForm | None], corrections: list[int] | None = None) -> EvaluationReport:
    counts = corrections if corrections is not None else [int(form is not None) for form in forms]
    return EvaluationReport([EpisodeResult(True, 5, None, form, -4.0, corrections=n) for form, n in zip(forms, counts)])


def test_the_quota_needs_both_the_corrections_and_where_they_are_on_the_negations() -> None:
    quota = CorrectionQuota(spoken=3, negations=2, episodes=10)
    excuse, negation = CorrectionForm.EXCUSE, CorrectionForm.NEGATION
    assert not quota.met(spoken([excuse, excuse, None, negation]), negations=True)
    assert quota.met(spoken([excuse, excuse, None, negation]), negations=False)
    assert not quota.met(spoken([negation, negation, None]), negations=True)
    assert quota.met(spoken([negation, negation, excuse]), negations=True)


def test_the_quota_waits_for_second_corrections_only_where_a_stage_speaks_them() -> None:
    quota = CorrectionQuota(spoken=2, negations=0, episodes=10, second=2)
    excuse = CorrectionForm.EXCUSE
    once = spoken([excuse, excuse, excuse], [1, 2, 1])
    assert not quota.met(once, negations=False, chains=True)
    assert quota.met(once, negations=False, chains=False)
    assert quota.met(spoken([excuse, excuse, excuse], [2, 1, 2]), negations=False, chains=True)
    assert CorrectionQuota(spoken=2, negations=0, episodes=10).met(once, negations=False, chains=True)


def test_the_quota_is_sized_like_the_test() -> None:
    assert CORRECTION_QUOTA.scaled(QUOTA_TEST_EPISODES) == CORRECTION_QUOTA
    assert CorrectionQuota(spoken=300, negations=150, episodes=3000, second=0) == CORRECTION_QUOTA
    assert CORRECTION_QUOTA.scaled(100) == CorrectionQuota(60, 30, 600)
    assert CORRECTION_QUOTA.scaled(2) == CorrectionQuota(2, 1, 12)  # never below one, unless none is asked for
    assert CorrectionQuota(300, 150, 3000, second=30).scaled(100) == CorrectionQuota(60, 30, 600, 6)
