"""The metrics every tool reports, and the language check's replacement sentences."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from lanrocli.envs.env import LanroEnv
from lanrocli.choices import Instruction
from lanrocli.envs.evaluation import METRIC_NAMES, EpisodeResult, EvaluationReport, evaluate
from lanrocli.envs.policies import make_policy
from lanrocli.language import TASK_VERBS, identifying_phrases, instruction


def episode(success: bool, challenge: str | None = None, corrected: bool = False, negation: bool = False) -> EpisodeResult:
    return EpisodeResult(success, 10, challenge, corrected, negation, -9.0)


def test_corrected_success_counts_only_episodes_with_a_spoken_correction() -> None:
    report = EvaluationReport(
        [
            episode(True),  # plain
            episode(True, "wrong_object"),  # a correction episode in which the arm made no mistake
            episode(False, "wrong_object", corrected=True),
            episode(True, "ambiguity", corrected=True, negation=True),
            episode(False, "ambiguity"),
        ]
    )
    assert (report.overall.episodes, report.overall.successes) == (5, 3)
    assert (report.correction_episodes.episodes, report.correction_episodes.successes) == (4, 2)
    assert (report.corrected.episodes, report.corrected.successes) == (2, 1)
    metrics = report.metrics()
    assert tuple(metrics) == METRIC_NAMES
    assert (metrics["corrected_episodes"], metrics["corrected_success"]) == (2, 0.5)
    assert (metrics["episodes_wrong_object"], metrics["success_wrong_object"]) == (2, 0.5)
    assert (metrics["corrected_episodes_wrong_object"], metrics["corrected_success_wrong_object"]) == (1, 0.0)
    assert (metrics["corrected_episodes_ambiguity"], metrics["corrected_success_ambiguity"]) == (1, 1.0)
    assert (metrics["episodes_common_ground"], metrics["corrected_success_common_ground"]) == (0, None)
    assert (metrics["corrected_episodes_negation"], metrics["corrected_success_negation"]) == (1, 1.0)
    record = report.as_dict()
    assert record["corrected"]["episodes"] == 2 and record["corrected"]["success"] == 0.5
    assert record["by_kind"]["wrong_object"]["corrected"]["episodes"] == 1
    assert record["correction_episode_success"] == 0.5


class Reader:
    """The oracle's actions, recording the sentence it was shown."""

    def __init__(self, task: str) -> None:
        self.oracle = make_policy("oracle", task)
        self.shown: list[np.ndarray] = []

    def reset(self, seed: int | None = None) -> None:
        self.oracle.reset(seed)

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        self.shown.append(observation["instruction"].copy())
        return self.oracle.act(observation, info)


@pytest.fixture(scope="module")
def env():
    env = LanroEnv("reach", objects=3, mode="colour_shape")
    yield env
    env.close()


def test_blank_shows_only_padding_and_true_the_instructors_sentence(env: LanroEnv) -> None:
    reader = Reader("reach")
    assert evaluate(env, reader, 2, seed=11, instruction_shown=Instruction.BLANK).overall.successes == 2
    assert all(not tokens.any() for tokens in reader.shown)
    reader.shown.clear()
    evaluate(env, reader, 1, seed=11)
    _, info = env.reset(seed=11)
    np.testing.assert_array_equal(reader.shown[0], env.vocabulary.encode(info["instruction_text"]))


def test_other_names_another_object_and_is_judged_on_it(env: LanroEnv) -> None:
    # The oracle ignores language and reaches the goal: with the true sentence it always wins, and with a
    # sentence naming another object it never does.
    assert evaluate(env, make_policy("oracle", "reach"), 5, seed=3).overall.successes == 5
    reader = Reader("reach")
    report = evaluate(env, reader, 5, seed=3, instruction_shown=Instruction.OTHER)
    assert report.overall.successes == 0
    for i in range(5):
        _, info = env.reset(seed=3 + i)
        objects = list(info["objects"])
        goal = info["goal_index"]
        text = env.vocabulary.decode(reader.shown[sum(r.length for r in report.results[:i])])
        named = {
            k for k, obj in enumerate(objects)
            for phrase in identifying_phrases(obj, objects[:k] + objects[k + 1 :])
            for verb in TASK_VERBS["reach"]
            if instruction(verb, phrase) == text
        }
        assert len(named) == 1 and goal not in named, text
