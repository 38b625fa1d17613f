"""The metrics every tool reports, the attention on the goal, stopping once enough was heard, and the
language check's replacement sentences."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lanrocli.core.choices import CorrectionForm, Instruction, Kind
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.policies import make_policy
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation.evaluate import EvaluationReport, evaluate
from lanrocli.evaluation.metrics import ATTENTION, FIGURES, METRIC_NAMES, PHASES, PLAIN, EpisodeResult
from lanrocli.language import TASK_VERBS, identifying_phrases, instruction

NEGATION, EXCUSE, EDIT = CorrectionForm.NEGATION, CorrectionForm.EXCUSE, CorrectionForm.EDIT


def episode(success: bool, challenge: str | None = None, form: CorrectionForm | None = None) -> EpisodeResult:
    return EpisodeResult(success, 10, challenge, form, -9.0)


def test_corrected_success_counts_only_episodes_with_a_spoken_correction() -> None:
    report = EvaluationReport(
        [
            episode(True),  # plain
            episode(True, "wrong_object"),  # a correction episode in which the arm made no mistake
            episode(False, "wrong_object", EXCUSE),
            episode(True, "ambiguity", NEGATION),
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
    assert (metrics["corrected_episodes_excuse"], metrics["corrected_success_excuse"]) == (1, 0.0)
    assert (metrics["corrected_episodes_edit"], metrics["corrected_success_edit"]) == (0, None)
    assert metrics[f"{ATTENTION}_{PLAIN}"] is None  # no attention was measured
    record = report.as_dict()
    assert record["corrected"]["episodes"] == 2 and record["corrected"]["success"] == 0.5
    assert record["by_kind"]["wrong_object"]["corrected"]["episodes"] == 1
    assert record["correction_episode_success"] == 0.5
    assert record["by_form"]["negation"] == {
        "episodes": 1,
        "success": 1.0,
        "ci": list(report.by_form()["negation"].interval),
    }
    assert record["by_form"]["edit"]["episodes"] == 0 and record[ATTENTION] is None
    # The registry reads each figure back from the record as the metrics have it.
    assert all(figure.read(record) == (metrics[figure.count], metrics[figure.name]) for figure in FIGURES)


def test_every_form_has_its_columns_and_older_records_keep_their_negations() -> None:
    for form in CorrectionForm:
        assert {f"corrected_episodes_{form}", f"corrected_success_{form}", f"{ATTENTION}_{form}"} <= set(METRIC_NAMES)
    (negation,) = [figure for figure in FIGURES if figure.name == "corrected_success_negation"]
    older = {"by_negation": {"with_negation": {"episodes": 4, "success": 0.25, "ci": [0, 1]}}}
    assert negation.read(older) == (4, 0.25)


results = st.builds(episode, st.booleans(), st.sampled_from([None, *Kind]), st.sampled_from([None, *CorrectionForm]))


@given(st.lists(results, max_size=30))
def test_the_forms_split_the_corrected_episodes(episodes: list[EpisodeResult]) -> None:
    report = EvaluationReport(episodes)
    forms = report.by_form().values()
    assert sum(rate.episodes for rate in forms) == report.corrected.episodes
    assert sum(rate.successes for rate in forms) == report.corrected.successes
    metrics = report.metrics()
    assert sum(metrics[f"corrected_episodes_{form}"] for form in CorrectionForm) == metrics["corrected_episodes"]


class Attentive:
    """The mistaken policy, with an attention that puts ``BEFORE`` on the slots while the episode's first
    sentence is shown and ``AFTER`` once a correction has extended it."""

    BEFORE = np.array([0.7, 0.3])
    AFTER = np.array([0.2, 0.8])

    def __init__(self) -> None:
        self.mistaken = make_policy("mistaken", "reach")
        self.first: np.ndarray | None = None

    def reset(self, seed: int | None = None) -> None:
        self.mistaken.reset(seed)
        self.first = None

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        return self.mistaken.act(observation, info)

    def attention(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        tokens = observation["instruction"]
        if self.first is None:
            self.first = tokens.copy()
        return self.BEFORE if np.array_equal(tokens, self.first) else self.AFTER


def test_attention_on_the_goal_is_averaged_over_the_steps_of_each_phase() -> None:
    settings = EnvSettings(objects=2, correction_rate=1.0, negations=True, negation_rate=0.5, kinds=("wrong_object",))
    env = LanroEnv("reach", settings)
    try:
        report = evaluate(env, Attentive(), 12, seed=40)
        goals = [env.reset(seed=40 + i)[1]["goal_index"] for i in range(12)]
    finally:
        env.close()
    spoken = {r.form for r in report.results if r.corrected}
    assert {NEGATION, EXCUSE} <= spoken or {NEGATION, EDIT} <= spoken, "both kinds of forms must be met"
    expected: dict[str, list[float]] = {}
    for result, goal in zip(report.results, goals):
        # Every step is of one phase: plain until the correction, then its form.
        assert sum(steps for _, steps in result.attention.values()) == result.length
        assert set(result.attention) <= {PLAIN, *([result.form] if result.form else [])}
        plain_steps = result.attention[PLAIN][1]
        expected.setdefault(PLAIN, []).extend([Attentive.BEFORE[goal]] * plain_steps)
        if result.form is not None:
            expected.setdefault(result.form, []).extend([Attentive.AFTER[goal]] * result.attention[result.form][1])
    shares = report.attention_on_goal()
    assert shares is not None and set(shares) == set(PHASES)
    for phase in PHASES:
        assert shares[phase] == (pytest.approx(np.mean(expected[phase])) if phase in expected else None)
    assert report.as_dict()[ATTENTION] == shares
    assert report.metrics()[f"{ATTENTION}_{PLAIN}"] == shares[PLAIN]


def test_a_policy_without_attention_reports_none() -> None:
    env = LanroEnv("reach", EnvSettings(objects=2))
    try:
        report = evaluate(env, make_policy("oracle", "reach"), 2, seed=0)
    finally:
        env.close()
    assert report.attention_on_goal() is None and all(not r.attention for r in report.results)


def test_enough_stops_at_the_first_episode_at_which_it_holds() -> None:
    settings = EnvSettings(objects=2, correction_rate=1.0, negations=True, negation_rate=0.5, kinds=("wrong_object",))
    env = LanroEnv("reach", settings)
    try:
        full = evaluate(env, make_policy("mistaken", "reach"), 10, seed=7)
        heard = [sum(r.negation for r in full.results[: i + 1]) for i in range(10)]
        assert heard[-1] >= 2
        stopped = evaluate(
            env, make_policy("mistaken", "reach"), 10, seed=7, enough=lambda r: r.by_form()["negation"].episodes >= 2
        )
    finally:
        env.close()
    assert len(stopped.results) == heard.index(2) + 1
    assert stopped.results == full.results[: len(stopped.results)]


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
            k
            for k, obj in enumerate(objects)
            for phrase in identifying_phrases(obj, objects[:k] + objects[k + 1 :])
            for verb in TASK_VERBS["reach"]
            if instruction(verb, phrase) == text
        }
        assert len(named) == 1 and goal not in named, text


def test_per_correction_counts_add_up() -> None:
    results = [
        EpisodeResult(success, 5, Kind.WRONG_OBJECT, None if n == 0 else CorrectionForm.EXCUSE, -4.0, corrections=n)
        for success, n in [(True, 0), (True, 1), (False, 1), (True, 2), (False, 2), (False, 2)]
    ]
    record = EvaluationReport(results).as_dict()
    after_second = record["by_index"]["2"]
    assert after_second["episodes"] == 3 and after_second["success"] == pytest.approx(1 / 3)
    assert record["corrected"]["episodes"] == 5  # the first correction counts every corrected episode
    only_one = [r for r in results if r.corrections == 1]
    assert len(only_one) + after_second["episodes"] == record["corrected"]["episodes"]
    metrics = EvaluationReport(results).metrics()
    assert metrics["corrected_episodes_after_2"] == 3


def test_named_first_tells_an_arm_that_reads_from_one_that_moves_on(env: LanroEnv) -> None:
    oracle = make_policy("oracle", "reach")
    reads = evaluate(env, oracle, 5, seed=3)
    assert reads.named_first.successes == 5 and reads.as_dict()["named_first"]["success"] == 1.0
    # The oracle ignores the sentence: told of another object, it still reaches the goal first.
    assert evaluate(env, oracle, 5, seed=3, instruction_shown=Instruction.OTHER).named_first.successes == 0
    # An arm that acts on a wrong object and then, corrected, on the goal wins without the goal first.
    corrected = LanroEnv("reach", objects=2, correction_rate=1.0)
    try:
        moved_on = evaluate(corrected, make_policy("mistaken", "reach"), 5, seed=3)
    finally:
        corrected.close()
    assert moved_on.overall.successes >= 4 and moved_on.named_first.successes == 0


def test_paraphrased_corrections_are_counted_by_phrasing() -> None:
    plain = EvaluationReport([episode(True, "ambiguity", EXCUSE)])
    assert "by_phrasing" not in plain.as_dict()
    results = [
        EpisodeResult(True, 10, Kind.AMBIGUITY, EXCUSE, -9.0, phrasing="i said"),
        EpisodeResult(False, 10, Kind.AMBIGUITY, NEGATION, -9.0, phrasing="the other"),
        EpisodeResult(True, 10, Kind.AMBIGUITY, EDIT, -9.0),  # no paraphrase fitted: the grammar's words
        EpisodeResult(True, 10, Kind.AMBIGUITY, None, -9.0),  # no correction spoken: not counted
    ]
    by_phrasing = EvaluationReport(results).as_dict()["by_phrasing"]
    assert {name: (r["episodes"], r["success"]) for name, r in by_phrasing.items()} == {
        "grammar": (1, 1.0),
        "i said": (1, 1.0),
        "the other": (1, 0.0),
    }
