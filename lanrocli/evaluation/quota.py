"""When the correction test stops: enough spoken corrections, negations and second corrections to judge an
agent on each, or a cap on the episodes (:mod:`lanrocli.train.testset` runs the test)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from lanrocli.core.choices import CorrectionForm
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation.evaluate import EvaluationReport
from lanrocli.evaluation.metrics import after_correction


@dataclass(frozen=True)
class CorrectionQuota:
    """When the correction test stops: once ``spoken`` episodes had a spoken correction, where negations are
    on ``negations`` of them a negation, and where the stage speaks chains of corrections ``second`` of them
    a second correction; or after ``episodes`` episodes whatever was heard, so that an agent that never errs,
    and so is never corrected, still ends. A second correction comes only where the arm acts on yet another
    wrong object after the first, a few episodes in a hundred, so runs ask for none (``second`` 0) and
    ``lanro eval --second-corrections`` asks for enough to judge the agent after one."""

    spoken: int
    negations: int
    episodes: int
    second: int = 0

    def met(self, report: EvaluationReport, negations: bool, chains: bool = False) -> bool:
        heard = report.by_form()[CorrectionForm.NEGATION].episodes
        seconds = report.rate(after_correction(2)).episodes
        return (
            report.corrected.episodes >= self.spoken
            and (not negations or heard >= self.negations)
            and (not chains or seconds >= self.second)
        )

    def scaled(self, test_episodes: int) -> CorrectionQuota:
        """This quota for a run whose ordinary test has ``test_episodes`` episodes instead of
        ``QUOTA_TEST_EPISODES``: a run that tests on few episodes (a quick run, a test's) spends as little here."""
        factor = test_episodes / QUOTA_TEST_EPISODES
        counts = (self.spoken, self.negations, self.episodes, self.second)
        return CorrectionQuota(*(max(1, math.ceil(n * factor)) if n else 0 for n in counts))


CORRECTION_QUOTA = CorrectionQuota(spoken=300, negations=150, episodes=3000)
"""The correction test's quota for a run tested on ``QUOTA_TEST_EPISODES`` episodes, and for ``lanro eval
--correction-test``: at least 300 spoken corrections put a 95% interval within about 6 points either side."""

QUOTA_TEST_EPISODES = 500
"""The ordinary test's size for which ``CORRECTION_QUOTA`` is written (the curricula's default)."""

CORRECTION_TEST_NEGATION_RATE = 0.5
"""Share of the correction test's spoken corrections that are negations, where the stage allows them."""


def correction_changes(stage: EnvSettings) -> dict[str, Any]:
    """The correction test's changes to a stage: every episode a correction episode, half the spoken
    corrections negations where the stage allows them."""
    negations = {"negation_rate": CORRECTION_TEST_NEGATION_RATE} if stage.negations else {}
    return {"correction_rate": 1.0, **negations}
