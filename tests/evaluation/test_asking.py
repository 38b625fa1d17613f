"""The calibrated rule for asking "which one?", and what evaluation records of questions."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from lanrocli.core.choices import Kind
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.policies import make_policy
from lanrocli.evaluation.asking import (
    CLEAR,
    AskingPolicy,
    asked_by_fits,
    conformal_threshold,
    questions_record,
)
from lanrocli.evaluation.evaluate import evaluate
from lanrocli.evaluation.metrics import EpisodeResult


def test_the_conformal_threshold_keeps_the_meant_object_at_the_level_on_fresh_scenes() -> None:
    rng = np.random.default_rng(0)
    level = 0.9
    covered = []
    for _ in range(200):
        threshold = conformal_threshold(rng.beta(2.0, 1.0, size=200), level)
        covered.append(np.mean(rng.beta(2.0, 1.0, size=2000) >= threshold))
    # Split conformal: coverage at least the level on average, and not much above it with 200 scenes.
    assert level <= np.mean(covered) <= level + 0.02


def test_the_conformal_threshold_is_the_rank_the_level_asks_for() -> None:
    weights = np.linspace(0.1, 1.0, 10)  # scores 1 - w: 0.0, 0.1, ..., 0.9
    assert conformal_threshold(weights, 0.5) == pytest.approx(1.0 - 0.5)  # ceil(11 * 0.5) = 6th score
    assert conformal_threshold(weights, 0.95) == 0.0  # ceil(11 * 0.95) = 11 > 10 scenes: keep everything
    with pytest.raises(ValueError, match="strictly between"):
        conformal_threshold(weights, 1.0)


class Weighing:
    """A batch policy whose attention is given: its actions are zeros."""

    def __init__(self, weights: np.ndarray) -> None:
        self.weights = weights

    def act_batch(self, observations: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray | None]:
        return np.zeros((4, 3)), self.weights


def test_the_rule_asks_unless_its_attention_keeps_exactly_one_object() -> None:
    weights = np.array([[0.98, 0.02, 0.0], [0.55, 0.45, 0.0], [0.4, 0.3, 0.3], [0.0, 0.0, 1.0]])
    actions, _ = AskingPolicy(Weighing(weights), threshold=0.3).act_batch({})
    assert actions.shape == (4, 4)
    assert actions[:, -1].tolist() == [-1.0, 1.0, 1.0, -1.0]
    with pytest.raises(ValueError, match="attention"):
        AskingPolicy(Weighing(None), 0.3).act_batch({})  # type: ignore[arg-type]


class AskingFirst:
    """A scripted policy that asks at its first step (the environment hears one question an episode)."""

    def __init__(self, name: str) -> None:
        self.policy = make_policy(name, "reach")

    def reset(self, seed: int | None = None) -> None:
        self.policy.reset(seed)

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        return np.append(self.policy.act(observation, info), 1.0)


def test_an_episodes_questions_answers_and_wrong_object_actions_are_in_its_record() -> None:
    env = LanroEnv("reach", objects=3, mode="colour_shape", correction_rate=1.0, max_corrections=2, questions=1)
    try:
        asked = evaluate(env, AskingFirst("mistaken"), 12, seed=4)
        for i, result in enumerate(asked.results):
            _, info = env.reset(seed=4 + i)
            assert result.questions == 1 and result.answers[0].startswith("actually the ")
            assert result.fits == info["fits"]
            assert result.wrong_objects >= 1  # the mistaken policy acts on a wrong object first
        plain = evaluate(env, AskingFirst("oracle"), 6, seed=4)
        assert all(r.wrong_objects == 0 and r.success for r in plain.results)
    finally:
        env.close()


def result(challenge: Kind | None, questions: int, success: bool, wrong: int, fits: int = 1) -> EpisodeResult:
    answers = ("actually the red cube",) * questions
    return EpisodeResult(success, 10, challenge, None, -9.0, answers=answers, wrong_objects=wrong, fits=fits)


def test_questions_are_reported_per_kind_of_episode_with_counts() -> None:
    results = [
        result(None, 0, True, 0),
        result(Kind.WRONG_OBJECT, 1, True, 1),
        result(Kind.AMBIGUITY, 1, True, 0, fits=2),
        result(Kind.AMBIGUITY, 1, False, 2, fits=3),
        result(Kind.AMBIGUITY, 0, True, 1, fits=2),
    ]
    record = questions_record(results)
    assert list(record) == [CLEAR, Kind.AMBIGUITY.value]  # only the kinds met, in the tables' order
    clear, ambiguous = record[CLEAR], record[Kind.AMBIGUITY.value]
    assert clear["episodes"] == 2 and clear["asked"]["episodes"] == 2 and clear["asked"]["success"] == 0.5
    assert ambiguous["questions"] == {
        "total": 2,
        "per_episode": 2 / 3,
        "ci": pytest.approx(ambiguous["questions"]["ci"]),
    }
    assert ambiguous["success"]["success"] == pytest.approx(2 / 3)
    assert ambiguous["wrong_objects"]["total"] == 3 and ambiguous["wrong_objects"]["per_episode"] == 1.0
    low, high = ambiguous["wrong_objects"]["ci"]
    assert low < 1.0 < high
    by_fits = asked_by_fits(results)
    assert {fits: rate["success"] for fits, rate in by_fits.items()} == {"1": 0.5, "2": 0.5, "3": 1.0}
