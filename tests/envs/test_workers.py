"""Environments in worker processes: the same episodes, results, frames and stopping point as in this
process, failures raised here with the worker's traceback, and no worker left behind."""

from __future__ import annotations

import functools
import gc
import subprocess
import sys
from collections.abc import Iterator

import numpy as np
import pytest

from lanrocli.envs.env import LanroEnv
from lanrocli.envs.policies import make_policy
from lanrocli.envs.settings import EnvSettings
from lanrocli.envs.workers import EnvWorker, WorkerError, make_envs
from lanrocli.evaluation.evaluate import EvaluationReport, evaluate

SETTINGS = EnvSettings(objects=3, mode="colour_shape", correction_rate=1.0, negations=True, negation_rate=0.5)
MAKE = functools.partial(LanroEnv, "push", SETTINGS)


def _made(in_workers: bool) -> Iterator[list]:
    made = make_envs(MAKE, 3, in_workers)
    yield made
    for env in made:
        env.close()


@pytest.fixture(scope="module")
def local() -> Iterator[list[LanroEnv]]:
    yield from _made(in_workers=False)


@pytest.fixture(scope="module")
def workers() -> Iterator[list[EnvWorker]]:
    yield from _made(in_workers=True)


def test_make_envs_puts_each_environment_where_asked(local: list[LanroEnv], workers: list[EnvWorker]) -> None:
    assert all(isinstance(env, LanroEnv) for env in local)
    assert all(isinstance(worker, EnvWorker) for worker in workers)
    assert len({worker._process.pid for worker in workers}) == 3


def test_a_worker_returns_what_its_environment_returns(local: list[LanroEnv], workers: list[EnvWorker]) -> None:
    obs_here, info_here = local[0].reset(seed=5)
    obs_there, info_there = workers[0].reset(seed=5)
    assert workers[0].task.name == "push" and workers[0].vocabulary == local[0].vocabulary
    for key in obs_here:
        np.testing.assert_array_equal(obs_there[key], obs_here[key])
    assert info_there["objects"] == info_here["objects"] and info_there["goal_index"] == info_here["goal_index"]
    action = np.array([0.3, -0.2, 0.1], dtype=np.float32)
    for _ in range(5):
        here, there = local[0].step(action), workers[0].step(action)
        np.testing.assert_array_equal(there[0]["observation"], here[0]["observation"])
        assert there[1:4] == here[1:4]


def test_a_scripted_policy_gets_the_same_results_in_workers(local: list[LanroEnv], workers: list[EnvWorker]) -> None:
    here = evaluate(local, make_policy("mistaken", "push"), 12, seed=21)
    there = evaluate(workers, make_policy("mistaken", "push"), 12, seed=21)
    assert there.results == here.results
    assert there.metrics() == here.metrics()
    assert any(r.corrected for r in here.results), "the episodes must hold corrections to compare"


def test_workers_stop_at_the_same_episode(local: list[LanroEnv], workers: list[EnvWorker]) -> None:
    def enough(report: EvaluationReport) -> bool:
        return report.by_form()["negation"].episodes >= 2

    here = evaluate(local, make_policy("mistaken", "push"), 20, seed=7, enough=enough)
    there = evaluate(workers, make_policy("mistaken", "push"), 20, seed=7, enough=enough)
    assert 2 <= len(here.results) < 20
    assert there.results == here.results


def test_a_gif_recorded_in_workers_is_the_one_recorded_here(tmp_path) -> None:  # type: ignore[no-untyped-def]
    make = functools.partial(LanroEnv, "reach", EnvSettings(objects=2), render_mode="rgb_array")
    for name, in_workers in (("here", False), ("there", True)):
        made = make_envs(make, 2, in_workers)
        try:
            evaluate(made, make_policy("oracle", "reach"), 4, seed=0, gif=tmp_path / f"{name}.gif")
        finally:
            for env in made:
                env.close()
    assert (tmp_path / "there.gif").read_bytes() == (tmp_path / "here.gif").read_bytes()


def test_a_failing_call_raises_here_with_the_workers_traceback(workers: list[EnvWorker]) -> None:
    workers[1].reset(seed=0)
    with pytest.raises(WorkerError, match="expected an action of size 3"):
        workers[1].step(np.zeros(99, dtype=np.float32))
    workers[1].reset(seed=0)  # the worker serves on after a failed call


def test_an_environment_that_cannot_be_built_is_a_clear_error() -> None:
    with pytest.raises(WorkerError, match="task must be one of"):
        make_envs(functools.partial(LanroEnv, "juggle", SETTINGS), 2, in_workers=True)


def test_closing_ends_the_worker_even_mid_step() -> None:
    worker = make_envs(MAKE, 1, in_workers=True)[0]
    worker.reset(seed=0)
    worker.step_async(np.zeros(3, dtype=np.float32))
    worker.close()
    assert not worker._process.is_alive()
    worker.close()  # twice is harmless


NEVER_CLOSED = """
import functools
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.settings import EnvSettings
from lanrocli.envs.workers import make_envs
envs = make_envs(functools.partial(LanroEnv, "push", EnvSettings()), 2, in_workers=True)
print("built", flush=True)
"""


def test_a_script_that_never_closes_its_workers_still_exits() -> None:
    """Workers ignore SIGTERM, which is how multiprocessing ends daemon children at exit: without the kill at
    exit this script waits for ever."""
    done = subprocess.run([sys.executable, "-c", NEVER_CLOSED], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "built\n"


def test_a_worker_dropped_without_closing_is_ended() -> None:
    worker = make_envs(MAKE, 1, in_workers=True)[0]
    process = worker._process
    del worker
    gc.collect()
    process.join(timeout=10)
    assert not process.is_alive()
