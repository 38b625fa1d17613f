"""Episodes in blocks over worker processes: the numbers of one process, a stopping rule that stops where one
process stops, a stop request heard while workers play, and a worker that dies named as such."""

from __future__ import annotations

import functools
import multiprocessing
import os
import signal

import pytest

from lanrocli.envs.env import LanroEnv
from lanrocli.envs.policies import make_policy
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation import blocks
from lanrocli.evaluation.blocks import MeasuringError, Workers, play
from lanrocli.evaluation.evaluate import EvaluationReport

MAKE_ENV = functools.partial(LanroEnv, "reach", EnvSettings(objects=2, correction_rate=0.5, max_episode_steps=12))


def played(workers: Workers, episodes: int, **options: object) -> EvaluationReport:
    policy = make_policy("mistaken", "reach")  # corrected in most episodes, so the tally has corrections to count
    return play(workers, workers.source(policy), MAKE_ENV, episodes, 40, **options)  # type: ignore[arg-type]


def test_two_workers_give_the_episodes_and_stopping_point_of_one(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(blocks, "CHUNK", 4)

    def enough(report: EvaluationReport) -> bool:  # depends on the outcomes, so on every episode before
        return report.corrected.episodes >= 7

    with Workers(1) as one, Workers(2) as two:
        assert played(one, 30).results == played(two, 30).results
        stopped = played(one, 30, enough=enough)
        assert played(two, 30, enough=enough).results == stopped.results
    assert 7 < len(stopped.results) < 30 and stopped.corrected.episodes == 7


def test_a_stop_request_is_heard_while_the_workers_play(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(blocks, "CHUNK", 4)
    heard: list[int] = []

    class Stop(Exception):
        pass

    def progress(taken: int) -> None:
        heard.append(taken)
        raise Stop  # at the first word: the workers are still starting, no episode has been taken

    with Workers(2) as two, pytest.raises(Stop):
        played(two, 30, progress=progress)
    assert heard == [0]


def test_a_worker_killed_in_a_block_is_named_and_nothing_is_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(blocks, "CHUNK", 4)
    killed: list[int] = []

    def progress(taken: int) -> None:
        if not killed:  # every child: a pool that an earlier test shut down may still be ending
            for worker in multiprocessing.active_children():
                killed.append(worker.pid or 0)
                os.kill(worker.pid or 0, signal.SIGKILL)

    with Workers(2) as two, pytest.raises(MeasuringError, match=r"killed, or ran out of memory.*Nothing"):
        played(two, 30, progress=progress)
    assert killed


def test_workers_are_counted_from_one_and_a_policy_they_cannot_copy_is_refused() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        Workers(0)

    class Local:
        def act(self, observation: dict, info: dict) -> None: ...

    with pytest.raises(ValueError, match="does not pickle"):
        Workers(2).source(Local())
    assert Workers(1).source(Local()).policy is not None  # this process needs no copy
