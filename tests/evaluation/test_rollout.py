"""Episodes side by side: the same episodes, results and stopping point as one after another; a policy that
answers a batch is asked once per step for all the episodes in progress."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from lanrocli.envs.env import LanroEnv
from lanrocli.envs.policies import make_policy
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation.evaluate import EvaluationReport, evaluate

SETTINGS = EnvSettings(objects=3, mode="colour_shape", correction_rate=1.0, negations=True, negation_rate=0.5)


@pytest.fixture(scope="module")
def envs() -> Iterator[list[LanroEnv]]:
    made = [LanroEnv("reach", SETTINGS) for _ in range(3)]
    yield made
    for env in made:
        env.close()


def test_a_scripted_policy_gets_the_same_results_side_by_side(envs: list[LanroEnv]) -> None:
    alone = evaluate(envs[0], make_policy("mistaken", "reach"), 12, seed=21)
    together = evaluate(envs, make_policy("mistaken", "reach"), 12, seed=21)
    assert together.results == alone.results
    assert together.metrics() == alone.metrics()
    assert any(r.corrected for r in alone.results), "the episodes must hold corrections to compare"


def test_side_by_side_stops_at_the_same_episode(envs: list[LanroEnv]) -> None:
    def enough(report: EvaluationReport) -> bool:
        return report.by_form()["negation"].episodes >= 2

    alone = evaluate(envs[0], make_policy("mistaken", "reach"), 20, seed=7, enough=enough)
    together = evaluate(envs, make_policy("mistaken", "reach"), 20, seed=7, enough=enough)
    assert 2 <= len(alone.results) < 20
    assert together.results == alone.results


class RowByRow:
    """A stateless policy that answers a batch, each row by a fixed function of that row alone."""

    def __init__(self) -> None:
        self.batches: list[int] = []

    def reset(self, seed: int | None = None) -> None:
        pass

    def act_batch(self, observations: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        rows = observations["observation"]
        self.batches.append(len(rows))
        weights = np.tile(np.array([1.0, 0.0, 0.0]), (len(rows), 1))
        return np.sin(7.0 * rows[:, :3]), weights


def test_a_batch_policy_answers_every_episode_in_progress_at_once(envs: list[LanroEnv]) -> None:
    one, three = RowByRow(), RowByRow()
    alone = evaluate(envs[0], one, 9, seed=3)
    together = evaluate(envs, three, 9, seed=3)
    assert set(one.batches) == {1}
    assert max(three.batches) == 3 and sum(three.batches) == sum(r.length for r in together.results)
    # The policy treats each row alone, so the episodes come out the same either way.
    assert together.results == alone.results


def test_a_gif_recorded_side_by_side_is_the_one_recorded_alone(tmp_path) -> None:  # type: ignore[no-untyped-def]
    made = [LanroEnv("reach", EnvSettings(objects=2), render_mode="rgb_array") for _ in range(2)]
    try:
        evaluate(made[0], make_policy("oracle", "reach"), 4, seed=0, gif=tmp_path / "alone.gif")
        evaluate(made, make_policy("oracle", "reach"), 4, seed=0, gif=tmp_path / "together.gif")
    finally:
        for env in made:
            env.close()
    assert (tmp_path / "together.gif").read_bytes() == (tmp_path / "alone.gif").read_bytes()
