"""A sweep's trials on Ray Tune: a local Ray instance started and stopped here, or a running cluster joined.

Each trial is a function trial of a ``tune.Tuner`` (:func:`run_trial`), with the resources it asks for;
Tune starts them as resources free up, at most ``max_concurrent`` at once, and a trial that fails is
recorded as failed while the others go on. Progress comes back through ``tune.report`` to a Tune callback
that passes it to the sweep's observer. Tune's own experiment state is not used to resume: every trial's
run folder holds its checkpoints, and a resumed sweep resumes those.

A stop request (Ctrl-C, SIGTERM) makes the sweep folder's stop file, which every running trial watches: each
writes a checkpoint and returns. Trials still waiting are then not started. Tune's own SIGINT handler,
which would end the trials without their checkpoints, is turned off.

Only ``lanro sweep`` imports this module, so only it needs Ray (``pip install -e '.[sweep]'``).
"""

from __future__ import annotations

import logging
import os
import signal
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import ray
from ray import tune

from lanrocli.sweep.protocol import (
    FAILED,
    FINISHED,
    NOT_STARTED,
    RUNNING,
    STOPPED,
    SweepObserver,
    TrialJob,
    TrialProgress,
)

QUIET = {
    "TUNE_DISABLE_SIGINT_HANDLER": "1",
    "RAY_AIR_NEW_OUTPUT": "0",
    "TUNE_DISABLE_AUTO_CALLBACK_LOGGERS": "1",
    "TUNE_PRINT_ALL_TRIAL_ERRORS": "0",
}
"""Tune's settings for a sweep: the stop request is ours, the display is ours, the results are in the run
folders, and errors are reported once, by the sweep."""


@dataclass(frozen=True)
class Resources:
    """Where the trials run and how many at once."""

    cpus_per_trial: float
    gpus_per_trial: float = 0.0
    max_concurrent: int | None = None
    """None: as many as the cluster's resources allow."""
    address: str | None = None
    """None: a local Ray instance, started and stopped by the sweep; ``auto`` or ``ray://HOST:PORT``: a
    running cluster."""
    cpus: float | None = None
    """The local instance's CPUs (None: the machine's)."""

    @classmethod
    def choose(
        cls, cpus_per_trial: float, gpus_per_trial: float, max_concurrent: int | None, address: str | None
    ) -> Resources:
        """The command line's choices: on this machine as many trials run at once as its CPUs hold (at least
        one, which gets what it asks for), on a cluster as many as the cluster's resources allow."""
        if address is not None:
            return cls(cpus_per_trial, gpus_per_trial, max_concurrent, address)
        machine = len(os.sched_getaffinity(0))
        concurrent = max_concurrent or max(1, int(machine // cpus_per_trial))
        return cls(cpus_per_trial, gpus_per_trial, concurrent, None, max(float(machine), cpus_per_trial * concurrent))

    def __str__(self) -> str:
        where = f"the Ray cluster at {self.address}" if self.address else f"a local Ray instance ({self.cpus:g} CPUs)"
        each = f"{self.cpus_per_trial:g} CPU(s)" + (
            f" and {self.gpus_per_trial:g} GPU(s)" if self.gpus_per_trial else ""
        )
        return f"{where}, {each} each" + (f", at most {self.max_concurrent} at once" if self.max_concurrent else "")


@dataclass
class SweepOutcome:
    statuses: dict[str, str] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)


def run_trial(config: dict[str, Any], jobs: dict[str, TrialJob]) -> None:
    """Tune's function trial: the trial named in ``config``. Training code loads in the worker, not here."""
    from lanrocli.sweep.trial import train_trial

    train_trial(jobs[config["trial"]])


class _Monitor(tune.Callback):
    """Passes the trials' reports to the observer and, once a stop is asked for, makes the stop file."""

    def __init__(self, observer: SweepObserver, stop_requested: Callable[[], bool], stop_file: Path) -> None:
        self.observer = observer
        self.stop_requested = stop_requested
        self.stop_file = stop_file
        self.running: set[str] = set()
        self.stopping = False

    def __getstate__(self) -> dict[str, Any]:
        """Nothing: Tune saves its experiment, callbacks included, to restore it; a sweep resumes from its run
        folders instead, and the display and the stop request live in this process only."""
        return {}

    def on_trial_start(self, iteration: int, trials: list[Any], trial: Any, **info: Any) -> None:
        self.running.add(trial.config["trial"])
        self.observer.update(TrialProgress(trial.config["trial"], RUNNING, line="started"))

    def on_trial_result(
        self, iteration: int, trials: list[Any], trial: Any, result: dict[str, Any], **info: Any
    ) -> None:
        self.observer.update(TrialProgress.from_dict(result))

    def on_trial_complete(self, iteration: int, trials: list[Any], trial: Any, **info: Any) -> None:
        self.running.discard(trial.config["trial"])

    def on_trial_error(self, iteration: int, trials: list[Any], trial: Any, **info: Any) -> None:
        self.running.discard(trial.config["trial"])
        self.observer.update(TrialProgress(trial.config["trial"], FAILED, line="failed"))

    def on_step_end(self, iteration: int, trials: list[Any], **info: Any) -> None:
        if not self.stopping and self.stop_requested():
            self.stopping = True
            self.stop_file.touch()
            self.observer.note("stopping: every running trial writes a checkpoint; trials not started yet wait")


class _AfterStop(tune.Stopper):
    """Ends the experiment once a stop was asked for and no trial runs any more, so that trials still
    waiting are not started only to stop again."""

    def __init__(self, monitor: _Monitor) -> None:
        self.monitor = monitor

    def __getstate__(self) -> dict[str, Any]:
        return {}

    def __call__(self, trial_id: str, result: dict[str, Any]) -> bool:
        return False

    def stop_all(self) -> bool:
        return self.monitor.stopping and not self.monitor.running


@contextmanager
def _settings(values: dict[str, str]) -> Iterator[None]:
    """Environment variables set for the block and restored after it."""
    saved = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


@contextmanager
def ray_instance(resources: Resources) -> Iterator[None]:
    """Ray for the block: the cluster at ``resources.address``, or a local instance stopped afterwards."""
    options: dict[str, Any] = {"logging_level": logging.ERROR, "log_to_driver": False}
    if resources.address is None:
        # Ray starts its workers at niceness 15 unless told otherwise: a trial beside a plain training would
        # get a small share of the cores. A local sweep's trials run at the priority of the command that
        # started them, as that training does; a cluster's workers keep what the cluster was started with.
        options |= {"num_cpus": resources.cpus, "include_dashboard": False, "_system_config": {"worker_niceness": 0}}
    # The local instance's processes inherit this mask: with SIGTERM blocked (Ray blocks SIGINT itself) a
    # SIGTERM to the whole process group reaches only this process, which stops the trials with their
    # checkpoints, rather than ending Ray under them. Ray's shutdown then takes a few seconds more.
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})
    try:
        ray.init(address=resources.address, **options)
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM})
    try:
        yield
    finally:
        ray.shutdown()


def _summary(error: BaseException) -> str:
    """The cause of a trial's failure in a line: the trial's own exception, not Ray's wrapping of it (the whole
    traceback is in Tune's error file)."""
    cause = getattr(error, "cause", None) or error
    text = str(cause).strip() or type(cause).__name__
    if isinstance(cause, ray.exceptions.RayActorError):
        text = "its process died (killed, or out of memory)"
    lines = [line for line in text.splitlines() if line.strip()]
    return f"{type(cause).__name__}: {lines[0] if lines else text}"


def run_sweep(
    jobs: list[TrialJob],
    resources: Resources,
    storage: Path,
    observer: SweepObserver,
    stop_requested: Callable[[], bool],
    stop_file: Path,
) -> SweepOutcome:
    """Run ``jobs`` on Ray (which the caller has started: :func:`ray_instance`); Tune's records go under
    ``storage``."""
    by_name = {job.name: job for job in jobs}
    monitor = _Monitor(observer, stop_requested, stop_file)
    trainable = tune.with_resources(
        tune.with_parameters(run_trial, jobs=by_name),
        {"cpu": resources.cpus_per_trial, "gpu": resources.gpus_per_trial},
    )
    tuner = tune.Tuner(
        trainable,
        param_space={"trial": tune.grid_search(list(by_name))},
        tune_config=tune.TuneConfig(
            max_concurrent_trials=resources.max_concurrent,
            trial_name_creator=lambda trial: trial.config["trial"],
            trial_dirname_creator=lambda trial: trial.config["trial"],
        ),
        run_config=tune.RunConfig(
            name=time.strftime("%Y-%m-%d_%H-%M-%S"),
            storage_path=str(storage.resolve()),
            verbose=0,
            callbacks=[monitor],
            stop=_AfterStop(monitor),
            failure_config=tune.FailureConfig(max_failures=0),
        ),
    )
    with _settings(QUIET):
        results = tuner.fit()
    outcome = SweepOutcome()
    for result in results:
        name = result.config["trial"]
        if result.error is not None:
            outcome.statuses[name] = FAILED
            outcome.errors[name] = f"{_summary(result.error)} (traceback: {Path(result.path) / 'error.txt'})"
        else:
            status = (result.metrics or {}).get("status")
            outcome.statuses[name] = status if status in (FINISHED, STOPPED) else NOT_STARTED
    return outcome
