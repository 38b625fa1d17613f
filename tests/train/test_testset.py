"""The correction test: its own held-out episodes, its settings, its quota, and the same record every time."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from lanrocli.agent.settings import BufferSettings, SACSettings
from lanrocli.choices import CorrectionForm
from lanrocli.envs.evaluation import EvaluationReport
from lanrocli.envs.figures import ATTENTION, PHASES, PLAIN, EpisodeResult
from lanrocli.envs.settings import EnvSettings
from lanrocli.language import Vocabulary
from lanrocli.language import vocabulary as vocabulary_module
from lanrocli.train.checkpoint import load_checkpoint, save_checkpoint
from lanrocli.train.seeds import correction_test_seed, held_out_seed
from lanrocli.train.testset import (
    CORRECTION_QUOTA,
    CORRECTION_TEST_NEGATION_RATE,
    QUOTA_TEST_EPISODES,
    CorrectionQuota,
    _load,
    _run,
    correction_test,
    measure,
)
from lanrocli.train.agent_policy import AgentPolicy
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


def _extend_grammar(monkeypatch: pytest.MonkeyPatch, *words: str) -> None:
    original = vocabulary_module.grammar_words
    monkeypatch.setattr(vocabulary_module, "grammar_words", lambda: sorted([*original(), *words]))
    vocabulary_module._grammar_vocabulary.cache_clear()


def test_a_checkpoint_evaluates_alike_after_the_grammar_gains_a_word(
    checkpoint: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    before = measure(checkpoint, 3).record
    try:
        _extend_grammar(monkeypatch, "aardvark")  # sorts first: had ids been rebuilt, every word would shift
        after = measure(checkpoint, 3).record
        assert after.pop("unknown_words") == ["aardvark"] and before.pop("unknown_words") == []
        assert after == before
        # The figures can tell: the same agent reading every id shifted by one attends otherwise.
        loaded = _load(checkpoint, "cpu", lambda _: {}, None)
        rebuilt = sorted([*loaded.policy.vocabulary.words[2:], "aardvark"])[:-1]
        policy = AgentPolicy(loaded.policy.agent, Vocabulary(rebuilt, loaded.policy.vocabulary.max_length))
        misread = _run(dataclasses.replace(loaded, policy=policy), 3, before["episodes_from"]["first_seed"])
        assert misread.as_dict()[ATTENTION] != before[ATTENTION]
    finally:
        vocabulary_module._grammar_vocabulary.cache_clear()


def test_a_checkpoint_that_stored_no_vocabulary_reads_with_the_one_it_was_trained_with(
    checkpoint: Path, tmp_path: Path
) -> None:
    contents = load_checkpoint(checkpoint, resumable=False)
    older = save_checkpoint(tmp_path / "stage-2-negations" / "checkpoint", dataclasses.replace(contents, vocabulary={}))
    assert measure(older, 3).record == measure(checkpoint, 3).record
