"""Seeds of the kinds of episodes a run meets, kept apart by construction.

Training environments are seeded once with 32-bit seeds (``TrainSettings.env_seed`` and the next few) and
run on from there. Evaluation and test episodes are reset one by one with seeds that carry their purpose,
the run's seed, the stage and a block number in separate 32-bit fields above the first 32 bits, so no
evaluation episode is a training or test episode, whatever the run's seed or the number of episodes.
Evaluation draws a new block for every evaluation (fresh episodes, yet the same ones when a resumed run
repeats that evaluation); the test set is block 0 of its stage and never changes. The correction test
(every episode a correction episode, as many as it takes to hear enough corrections) has a purpose of its
own, so its episodes are none of the ordinary test's either, and so has each generalisation split, the
question test, the scenes its rule for asking is calibrated on, and the benchmark's protocols.
"""

from __future__ import annotations

import zlib
from enum import IntEnum

from lanrocli.core.choices import Split

FIELD = 1 << 32
"""Width of each field of a seed; run seed, stage, block and episode index must each stay below it."""


class Purpose(IntEnum):
    EVALUATION = 1
    TEST = 2
    CORRECTION_TEST = 3
    SPLIT_TEST = 4
    BENCHMARK = 5
    CALIBRATION = 6
    QUESTION_TEST = 7


def first_seed(purpose: Purpose, run_seed: int, stage: int, block: int = 0) -> int:
    """The seed of episode 0 of a block; episode i uses this plus i (i < 2**32)."""
    for name, value in (("run seed", run_seed), ("stage", stage), ("block", block)):
        if not 0 <= value < FIELD:
            raise ValueError(f"{name} must lie in [0, 2**32), got {value}")
    return (((int(purpose) * FIELD + run_seed) * FIELD + stage) * FIELD + block) * FIELD


def evaluation_seed(run_seed: int, stage: int, evaluation: int) -> int:
    """First seed of the ``evaluation``-th evaluation (counted from 0) of a stage."""
    return first_seed(Purpose.EVALUATION, run_seed, stage, evaluation)


def held_out_seed(run_seed: int, stage: int) -> int:
    """First seed of a stage's held-out test episodes."""
    return first_seed(Purpose.TEST, run_seed, stage)


def correction_test_seed(run_seed: int, stage: int) -> int:
    """First seed of a stage's held-out correction-test episodes."""
    return first_seed(Purpose.CORRECTION_TEST, run_seed, stage)


def split_test_seed(run_seed: int, stage: int, split: Split) -> int:
    """First seed of a generalisation split's held-out episodes: each split is a block of its own."""
    return first_seed(Purpose.SPLIT_TEST, run_seed, stage, list(Split).index(split))


def calibration_seed(run_seed: int, stage: int) -> int:
    """First seed of the scenes a rule for asking questions is calibrated on: never a test's."""
    return first_seed(Purpose.CALIBRATION, run_seed, stage)


def question_test_seed(run_seed: int, stage: int) -> int:
    """First seed of a stage's held-out question-test episodes."""
    return first_seed(Purpose.QUESTION_TEST, run_seed, stage)


def benchmark_seed(task: str, protocol: int) -> int:
    """First seed of a benchmark protocol's episodes for ``task`` (:mod:`lanrocli.evaluation.protocols`):
    fixed by the task's name and the protocol's number alone, so every lab plays the same ones."""
    return first_seed(Purpose.BENCHMARK, zlib.crc32(task.encode()), protocol)
