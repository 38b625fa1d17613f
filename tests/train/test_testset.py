"""The correction test: its own held-out episodes, its settings, its quota, and the same record every time."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lanrocli.agent.policy import AgentPolicy
from lanrocli.agent.settings import BufferSettings, SACSettings
from lanrocli.core.seeds import correction_test_seed, held_out_seed
from lanrocli.envs.policies import arm_view
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation.metrics import ATTENTION, PHASES, PLAIN
from lanrocli.evaluation.quota import CORRECTION_TEST_NEGATION_RATE, CorrectionQuota
from lanrocli.language import Vocabulary
from lanrocli.language import vocabulary as vocabulary_module
from lanrocli.tasks import OracleMemory, make_task
from lanrocli.train import testset as testset_module
from lanrocli.train.checkpoint import load_checkpoint, save_checkpoint
from lanrocli.train.testset import (
    _load,
    _run,
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


def test_the_correction_test_has_episodes_and_settings_of_its_own_and_repeats_itself(checkpoint: Path) -> None:
    quota = CorrectionQuota(spoken=50, negations=25, episodes=4)  # an untrained agent is hardly ever corrected
    first = correction_test(checkpoint, quota)
    record = first.record
    assert record["episodes_from"] == {"correction_test": True, "first_seed": correction_test_seed(3, 1)}
    assert first.first_seed not in range(held_out_seed(3, 1), held_out_seed(3, 1) + 10_000)
    assert record["env"]["correction_rate"] == 1.0 and record["env"]["negation_rate"] == CORRECTION_TEST_NEGATION_RATE
    assert record["episodes"] == 4 and record["correction_episodes"] == 4 and not record["quota_met"]
    assert record["quota"] == {"spoken": 50, "negations": 25, "episodes": 4, "second": 0}
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


class _WrongTwice:
    """Reaches a wrong object, after the first correction the other wrong one, after the second the goal: the
    arm that chains of corrections are for."""

    def __init__(self, policy: AgentPolicy) -> None:
        self.agent, self.vocabulary = policy.agent, policy.vocabulary  # the record and the episodes read them
        self.task = make_task("reach")

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        goal = int(info["goal_index"])
        wrong = [k for k in range(len(info["objects"])) if k != goal]
        said = 0 if info["correction"] is None else int(info["correction"]["index"])
        target = wrong[said] if said < len(wrong) else goal
        return self.task.oracle(arm_view(observation, info, target), OracleMemory())


def test_the_correction_test_runs_on_until_enough_second_corrections_were_spoken(
    checkpoint: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    chains = EnvSettings(objects=3, mode="colour_shape", correction_rate=0.5, max_corrections=2, max_episode_steps=60)
    settings = TrainSettings(task="reach", env=chains, seed=3, stage=1, buffer=BufferSettings(size=10))
    trainer = Trainer(settings, SACSettings(hidden_size=16, obs_size=16, architecture="objects"))
    try:
        path = trainer.save(tmp_path / "stage-2-chains" / "checkpoint", resumable=False)
    finally:
        trainer.close()
    loaded = testset_module.load_policy
    monkeypatch.setattr(testset_module, "load_policy", lambda *a: (lambda s, p: (s, _WrongTwice(p)))(*loaded(*a)))
    first_only = correction_test(path, CorrectionQuota(spoken=3, negations=0, episodes=40)).report.results
    waiting = correction_test(path, CorrectionQuota(spoken=3, negations=0, episodes=40, second=5))
    seconds = [i for i, r in enumerate(waiting.report.results) if r.corrections >= 2]
    assert len(seconds) == 5 and seconds[-1] == len(waiting.report.results) - 1  # it stops at the fifth
    assert len(first_only) < len(waiting.report.results) and waiting.record["quota_met"]
    assert waiting.record["quota"]["second"] == 5 == waiting.record["by_index"]["2"]["episodes"]
    assert waiting.report.results[: len(first_only)] == first_only  # the same episodes, run on
    # A stage that corrects once an episode never speaks a second correction: asking for one is an error.
    with pytest.raises(ValueError, match="never spoken"):
        correction_test(checkpoint, CorrectionQuota(spoken=1, negations=0, episodes=4, second=1))


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
