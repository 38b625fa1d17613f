"""``lanro sweep``'s own process: the trials still to run handed to Ray and shown as they go, then what became
of every trial, those that had ended before the sweep was resumed included.

It imports Ray, through :mod:`lanrocli.sweep.execute`, so only ``lanro sweep`` imports it; the training
happens in Ray's workers (:mod:`lanrocli.sweep.trial`).
"""

from __future__ import annotations

from pathlib import Path

from rich.console import Console

from lanrocli.config.curriculum import Curriculum
from lanrocli.sweep.display import SweepDisplay
from lanrocli.sweep.execute import Resources, SweepOutcome, ray_instance, run_sweep
from lanrocli.sweep.plan import RAY_FOLDER, STOP_FILE, Trial, trial_jobs
from lanrocli.sweep.protocol import ENDED_BEFORE, PENDING, TrialProgress
from lanrocli.train.stop import StopRequest


def run_trials(
    out: Path,
    trials: list[tuple[Trial, Curriculum]],
    cpus_per_trial: float,
    gpus_per_trial: float,
    max_concurrent: int | None,
    address: str | None,
) -> tuple[Console, SweepOutcome]:
    """Run the trials of the sweep in ``out`` that have not ended, on the resources the options ask for, and
    return the console the sweep was shown on and every trial's status (and the errors of those that
    failed). A second Ctrl-C raises ``KeyboardInterrupt``; the stop file is gone either way, so a resumed
    sweep does not stop at once."""
    jobs = trial_jobs(out, trials, "cuda" if gpus_per_trial > 0 else "cpu")
    waiting = {job.name for job in jobs}
    rows = [TrialProgress(trial.name, PENDING if trial.name in waiting else ENDED_BEFORE) for trial, _ in trials]
    resources = Resources.choose(cpus_per_trial, gpus_per_trial, max_concurrent, address)
    display = SweepDisplay.for_terminal(rows)
    outcome = SweepOutcome()
    if jobs:
        display.console.print(f"{len(jobs)} trial(s) of {len(trials)} to run on {resources}", highlight=False)
        try:
            # Ray's start installs a SIGTERM handler of its own: the stop request's comes after it.
            with ray_instance(resources), StopRequest() as stop, display:
                outcome = run_sweep(jobs, resources, out / RAY_FOLDER, display, stop.requested, out / STOP_FILE)
        finally:
            (out / STOP_FILE).unlink(missing_ok=True)
    statuses = {row.trial: row.status for row in rows} | outcome.statuses
    return display.console, SweepOutcome(statuses, outcome.errors)
