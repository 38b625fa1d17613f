"""The sweep's resources by default, the priority of its trials, and failures told in a line."""

from __future__ import annotations

import os

from lanrocli.sweep.execute import Resources, _summary
from lanrocli.train.errors import RunError


def test_a_trial_takes_a_cpu_per_environment_worker_and_one_for_its_learner() -> None:
    cores = len(os.sched_getaffinity(0))
    two = Resources.choose(envs=2, cpus_per_trial=None, gpus_per_trial=0, max_concurrent=None, address=None)
    assert two.cpus_per_trial == 3 and two.max_concurrent == max(1, cores // 3)
    assert two.cpus == max(cores, 3 * two.max_concurrent)  # one trial always fits, even on two cores
    one = Resources.choose(envs=1, cpus_per_trial=None, gpus_per_trial=0, max_concurrent=None, address=None)
    assert one.cpus_per_trial == 1 and one.max_concurrent == cores
    asked = Resources.choose(envs=2, cpus_per_trial=1, gpus_per_trial=0.5, max_concurrent=4, address=None)
    assert (asked.cpus_per_trial, asked.gpus_per_trial, asked.max_concurrent, asked.cpus) == (1, 0.5, 4, max(cores, 4))
    cluster = Resources.choose(envs=2, cpus_per_trial=None, gpus_per_trial=0, max_concurrent=None, address="auto")
    assert cluster.max_concurrent is None and cluster.cpus is None
    assert str(cluster) == "the Ray cluster at auto, 3 CPU(s) each"


def test_a_failure_is_told_by_the_trials_own_exception() -> None:
    class Wrapped(Exception):
        cause = RunError("runs/x is in use: process 12 is writing this run.\nWait for it to end.")

    assert _summary(Wrapped("Ray's traceback ...")) == "RunError: runs/x is in use: process 12 is writing this run."


def test_a_local_sweeps_trials_run_at_the_priority_of_the_command() -> None:
    import ray

    from lanrocli.sweep.execute import ray_instance

    @ray.remote
    def niceness() -> int:
        return os.nice(0)

    with ray_instance(Resources(cpus_per_trial=1, cpus=1)):
        assert ray.get(niceness.remote()) == os.nice(0)  # Ray's own default would be 15
