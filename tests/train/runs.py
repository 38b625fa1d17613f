"""A tiny three-stage curriculum and the means to run it in a real process, interrupt it and compare runs:
shared by the tests of the pipeline and of its faults."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import NamedTuple

from lanrocli.train.runfolder import LATEST, METRICS, read_pointer
from lanrocli.train.runstate import RunState

TINY = """\
name: tiny
task: reach
seed: 5
envs: {envs}
learning_starts: 40
agent: {{batch_size: 16}}
buffer: {{size: 4000}}
eval: {{every: 40, episodes: 2}}
test: {{episodes: 2}}
stages:
  - name: first
    env: {{objects: 2, max_episode_steps: 15}}
    budget: {{steps: 80}}
    promote: {{success: 1.0}}
  - name: second
    env: {{objects: 2, correction_rate: 0.5, max_episode_steps: 20}}
    budget: {{steps: 80}}
  - name: third
    env: {{objects: 3, mode: colour_shape, correction_rate: 0.5, negations: true, max_episode_steps: 20}}
    budget: {{steps: 80}}
holdout: {{pairs: [red cube], correction_words: [block, brick, barrel], late_corrections: [1, 4], paraphrase: true}}
"""


def tiny(tmp_path: Path, envs: int = 1) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY.format(envs=envs))
    return path


class Baseline(NamedTuple):
    curriculum: Path
    out: Path


def lanro(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    """``lanro ARGS`` in a process of its own, in a new session, so a signal can go to its whole process
    group as a terminal's Ctrl-C does."""
    return subprocess.Popen(
        [sys.executable, "-c", "from lanrocli.cli.app import app; app()", *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )


def train(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    return lanro(["train", *args], cwd)


def finish(process: subprocess.Popen[str], timeout: float = 300) -> str:
    """Wait for ``process`` to end well and return its output, or fail with the output."""
    output = process.communicate(timeout=timeout)[0]
    assert process.returncode == 0, output
    return output


def rows(out: Path) -> list[dict[str, str]]:
    with open(out / METRICS, newline="") as f:
        return list(csv.DictReader(f))


def wait_until(ready: object, process: subprocess.Popen[str], what: str, poll: float = 0.02) -> None:
    """Poll ``ready()`` until it holds; fail if ``process`` ends or two minutes pass first."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if ready():  # type: ignore[operator]
            return
        time.sleep(poll)
    raise AssertionError(f"the run ended or stalled before {what}")


def wait_for_rows(out: Path, n: int, process: subprocess.Popen[str]) -> None:
    wait_until(lambda: (out / METRICS).is_file() and len(rows(out)) >= n, process, f"{n} evaluations")


def scalars(out: Path, tag: str) -> list[tuple[int, float]]:
    """The points of ``tag`` in the TensorBoard events of the run in ``out``, every process's file read in turn,
    as TensorBoard shows them: what a resumed run purged is gone."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    accumulator = EventAccumulator(str(out))
    accumulator.Reload()
    return [(event.step, event.value) for event in accumulator.Scalars(tag)]


def outcome(out: Path) -> tuple[list[dict[str, str]], list[tuple[str, int, int, str]], list[dict]]:
    """Everything a run produced that must not depend on interruptions (wall time aside)."""
    metrics = [{k: v for k, v in r.items() if k != "wall_time"} for r in rows(out)]
    saved = json.loads((read_pointer(out / LATEST) / "state.json").read_text())
    state = RunState.from_dict(saved["extra"]["run"])
    stages = [(r.name, r.start, r.end, r.ended) for r in state.results]
    tests = [json.loads(path.read_text()) for path in sorted(out.glob("stage-*/test.json"))]
    return metrics, stages, tests
