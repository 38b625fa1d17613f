"""The sweep's resources by default, and failures told in a line."""

from __future__ import annotations

import os

from lanrocli.sweep.execute import Resources, _summary
from lanrocli.train.errors import RunError


def test_a_trial_takes_the_cpus_asked_and_as_many_run_at_once_as_the_machine_holds() -> None:
    cores = len(os.sched_getaffinity(0))
    default = Resources.choose(cpus_per_trial=1.0, gpus_per_trial=0, max_concurrent=None, address=None)
    assert default.cpus_per_trial == 1 and default.max_concurrent == cores and default.cpus == cores
    wide = Resources.choose(cpus_per_trial=cores + 1, gpus_per_trial=0, max_concurrent=None, address=None)
    assert wide.max_concurrent == 1 and wide.cpus == cores + 1  # one trial always fits, whatever it asks
    asked = Resources.choose(cpus_per_trial=1, gpus_per_trial=0.5, max_concurrent=4, address=None)
    assert (asked.cpus_per_trial, asked.gpus_per_trial, asked.max_concurrent, asked.cpus) == (1, 0.5, 4, max(cores, 4))
    cluster = Resources.choose(cpus_per_trial=3, gpus_per_trial=0, max_concurrent=None, address="auto")
    assert cluster.max_concurrent is None and cluster.cpus is None
    assert str(cluster) == "the Ray cluster at auto, 3 CPU(s) each"


def test_a_failure_is_told_by_the_trials_own_exception() -> None:
    class Wrapped(Exception):
        cause = RunError("runs/x is in use: process 12 is writing this run.\nWait for it to end.")

    assert _summary(Wrapped("Ray's traceback ...")) == "RunError: runs/x is in use: process 12 is writing this run."
