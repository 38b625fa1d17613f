"""Evaluation and test episodes never meet each other or a training episode."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from lanrocli.core.seeds import FIELD, Purpose, correction_test_seed, evaluation_seed, first_seed, held_out_seed
from lanrocli.train.trainer import TrainSettings

field = st.integers(0, FIELD - 1)


@given(run_seed=field, stage=st.integers(0, 20), block=field, index=st.integers(0, 100_000))
def test_evaluation_and_test_seeds_lie_above_every_training_seed(
    run_seed: int, stage: int, block: int, index: int
) -> None:
    training = TrainSettings(seed=run_seed, stage=stage, envs=64).env_seed + 63
    assert training < FIELD + 64 < evaluation_seed(run_seed, stage, block) + index
    assert training < held_out_seed(run_seed, stage) + index


@given(
    a=st.tuples(st.sampled_from(list(Purpose)), field, field, field, field),
    b=st.tuples(st.sampled_from(list(Purpose)), field, field, field, field),
)
def test_different_blocks_never_share_a_seed(a: tuple, b: tuple) -> None:
    (purpose_a, seed_a, stage_a, block_a, i), (purpose_b, seed_b, stage_b, block_b, j) = a, b
    same_episode = (
        first_seed(purpose_a, seed_a, stage_a, block_a) + i == first_seed(purpose_b, seed_b, stage_b, block_b) + j
    )
    assert same_episode == (a == b)


def test_the_test_set_is_not_any_evaluation() -> None:
    evaluations = {evaluation_seed(0, 0, k) + i for k in range(50) for i in range(100)}
    assert not evaluations & {held_out_seed(0, 0) + i for i in range(500)}


def test_the_correction_test_meets_no_test_or_evaluation_episode() -> None:
    corrections = {correction_test_seed(0, 0) + i for i in range(3000)}
    assert not corrections & {held_out_seed(0, 0) + i for i in range(3000)}
    assert not corrections & {evaluation_seed(0, 0, k) + i for k in range(50) for i in range(100)}


def test_fields_out_of_range_are_refused() -> None:
    with pytest.raises(ValueError, match="block"):
        evaluation_seed(0, 0, FIELD)
    with pytest.raises(ValueError, match="run seed"):
        held_out_seed(-1, 0)
