"""lanro sweep on a real local Ray instance: two seeds of the tiny curriculum, one CPU each, finished,
interrupted with SIGINT, killed with SIGKILL, and with one trial's process killed under it (trials run at the
priority of the command). Interrupted sweeps resumed with --resume end with the same run folders, trial by
trial, as the uninterrupted one."""

from __future__ import annotations

import json
import os
import signal
import subprocess
from pathlib import Path

import pytest

from lanrocli.sweep.plan import SWEEP_FILE
from lanrocli.train.report import run_ended
from lanrocli.train.runfolder import REPORT
from lanrocli.train.writing import LOCK
from tests.train.runs import Baseline, finish, lanro, outcome, rows, tiny, wait_until

pytestmark = pytest.mark.slow

SEEDS = ["--seeds", "0", "1", "--cpus-per-trial", "1", "--max-concurrent", "2"]
TRIALS = ("seed=0", "seed=1")


def sweep(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    return lanro(["sweep", *args], cwd)


@pytest.fixture(scope="module")
def straight(tmp_path_factory: pytest.TempPathFactory) -> Baseline:
    """The two-seed sweep, never interrupted: what every interrupted one must end up equal to."""
    folder = tmp_path_factory.mktemp("straight")
    path = tiny(folder)
    finish(sweep([str(path), "--out", "sweep", *SEEDS], folder))
    return Baseline(path, folder / "sweep")


def started(out: Path, process: subprocess.Popen[str]) -> None:
    """Wait until every trial has evaluated at least once."""
    wait_until(
        lambda: all((out / t / "metrics.csv").is_file() and len(rows(out / t)) >= 1 for t in TRIALS),
        process,
        "evaluations",
    )


def test_a_sweep_makes_an_ordinary_run_folder_per_trial(straight: Baseline, tmp_path: Path) -> None:
    out = straight.out
    assert {entry.name for entry in out.iterdir()} == {SWEEP_FILE, ".ray", *TRIALS}
    for trial in TRIALS:
        assert (out / trial / REPORT).is_file() and run_ended(out / trial)
    report = lanro(["report", str(out), "--json"], tmp_path)
    data = json.loads(finish(report))
    for stage in data["groups"][0]["stages"]:
        assert stage["metrics"]["success"]["runs"] == 2 and len(stage["metrics"]["success"]["ci"]) == 2
    finish(lanro(["plot", str(out), "--out", str(tmp_path / "curves.png")], tmp_path))
    assert (tmp_path / "curves.png").stat().st_size > 10_000
    again = finish(sweep([str(straight.curriculum), "--out", str(out), *SEEDS, "--resume"], tmp_path))
    assert "2 of 2 trials finished" in again  # finished trials are left alone, and Ray is not even started
    assert "to run on" not in again


@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGKILL], ids=["SIGINT", "SIGKILL"])
def test_an_interrupted_sweep_resumes_to_the_same_runs(straight: Baseline, tmp_path: Path, how: signal.Signals) -> None:
    path = tiny(tmp_path)
    out = tmp_path / "sweep"
    process = sweep([str(path), "--out", "sweep", *SEEDS], tmp_path)
    started(out, process)
    os.killpg(process.pid, how)  # the whole process group, as a terminal's Ctrl-C, or a kill of the job
    output = process.communicate(timeout=120)[0]
    if how == signal.SIGINT:
        assert process.returncode == 130, output
        assert "resume with: lanro sweep --out sweep --resume" in output
        assert all((out / t / "latest").is_file() and not run_ended(out / t) for t in TRIALS)
    finish(sweep([str(path), "--out", "sweep", *SEEDS, "--resume"], tmp_path))
    for trial in TRIALS:
        assert outcome(out / trial) == outcome(straight.out / trial), trial


def test_a_trial_that_crashes_leaves_the_others_to_finish(tmp_path: Path) -> None:
    path = tiny(tmp_path)
    out = tmp_path / "sweep"
    process = sweep([str(path), "--out", "sweep", *SEEDS], tmp_path)
    started(out, process)
    holder = int((out / "seed=1" / LOCK).read_text().split()[-1])  # the Ray worker that runs trial seed=1
    assert os.getpriority(os.PRIO_PROCESS, holder) == os.nice(0)  # the command's priority; Ray's own is 15
    os.kill(holder, signal.SIGKILL)
    output = process.communicate(timeout=180)[0]
    assert process.returncode == 1, output
    assert "trial seed=1 failed" in output and "1 of 2 trials finished" in output
    assert run_ended(out / "seed=0") and not run_ended(out / "seed=1")
