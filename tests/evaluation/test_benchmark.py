"""Scoring any policy on a benchmark protocol: a policy written outside the package, by the API and by the
command line; several workers against one; policies that fail, named by episode."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import lanrocli
from lanrocli.evaluation import blocks
from lanrocli.evaluation.protocols import PROTOCOL_VERSION
from lanrocli.evaluation.rollout import PolicyError
from lanrocli.pretrained import agent_path
from lanrocli.train.trainer import load_policy

OUTSIDE_POLICY = '''
import numpy as np


def make_policy(task):
    """Heads for the object the instructor means, read from the episode's info."""

    def act(observation, info):
        hand = observation["observation"][:3]
        goal = info["object_positions"][int(info["goal_index"])]
        return np.clip((goal - hand) * 10.0, -1.0, 1.0).astype(np.float32)

    return act


def make_raising(task):
    def act(observation, info):
        if info["correction"] is not None or observation["observation"][2] < 10.0:
            raise RuntimeError("no idea")
    return act


def make_misshapen(task):
    return lambda observation, info: np.zeros(5)


def make_not_finite(task):
    return lambda observation, info: np.full(3, np.nan)
'''

FIGURES = ("episodes", "success", "success_ci", "mean_length", "mean_return", "by_kind", "by_form", "corrected")


@pytest.fixture(scope="module")
def outside(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A policy file in a folder of its own, which nothing in lanro imports."""
    folder = tmp_path_factory.mktemp("outside")
    (folder / "my_policy.py").write_text(OUTSIDE_POLICY)
    return folder


def lanro(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-c", "from lanrocli.cli.app import app; app()", *args]
    return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=300)


def test_an_outside_policy_scores_the_same_by_the_api_and_the_command_line(outside: Path) -> None:
    spec = str(outside / "my_policy.py") + ":make_policy"
    record = lanrocli.evaluate(spec, "reach", "test", episodes=12)
    assert record["benchmark"] == {
        "protocol": "test",
        "version": PROTOCOL_VERSION,
        "first_seed": record["benchmark"]["first_seed"],
        "complete": False,
    }
    assert record["episodes"] == 12 and record["success"] > 0.0
    shell = lanro("eval", "my_policy:make_policy", "--task", "reach", "--episodes", "12", "--json", cwd=outside)
    assert shell.returncode == 0, shell.stderr
    printed = json.loads(shell.stdout)
    assert {key: printed[key] for key in FIGURES} == {key: record[key] for key in FIGURES}
    assert printed["benchmark"] == record["benchmark"]


def test_a_policy_that_fails_is_named_by_its_episode_and_exits_2(outside: Path) -> None:
    for factory, words in (
        ("make_raising", "raised RuntimeError in episode 0"),
        ("make_misshapen", "has shape (5,); the task's actions have shape (3,)"),
        ("make_not_finite", "is not finite"),
    ):
        shell = lanro(
            "eval", f"my_policy.py:{factory}", "--task", "reach", "--episodes", "3", "--workers", "1", cwd=outside
        )
        assert shell.returncode == 2, shell.stderr
        assert words in " ".join(shell.stderr.split()), shell.stderr
    with pytest.raises(PolicyError, match="episode 0"):
        lanrocli.evaluate(lambda observation, info: np.zeros(2), "reach", episodes=2)


def test_bad_benchmark_requests_are_refused_with_exit_2(outside: Path) -> None:
    for args, words in (
        (("oracle", "--protocol", "tset"), "unknown protocol 'tset'"),
        (("my_policy:make_policy",), "add --task"),
        (("my_policy:nothing", "--task", "reach"), "has no function 'nothing'"),
        (("oracle", "--protocol", "test", "--seed", "3"), "fixes its episodes"),
        (("oracle", "--workers", "2"), "add --protocol"),
    ):
        shell = lanro("eval", *args, cwd=outside)
        assert shell.returncode == 2, (args, shell.stderr)
        assert words in " ".join(shell.stderr.split()), shell.stderr


def test_several_workers_give_the_numbers_of_one(monkeypatch: pytest.MonkeyPatch) -> None:
    """A trained agent's batched network, the episodes cut into blocks over two processes: the same
    outcomes, lengths and attention, to the last bit, as one process playing them all."""
    _, agent = load_policy(agent_path(Path("push")))
    monkeypatch.setattr(blocks, "CHUNK", 5)
    one = lanrocli.evaluate(agent, "push", "correction_test", episodes=14)
    two = lanrocli.evaluate(agent, "push", "correction_test", episodes=14, workers=2)
    assert one == two
    assert one["attention_on_goal"] is not None and one["episodes"] == 14


def test_a_policy_that_does_not_pickle_is_refused_for_several_workers() -> None:
    class Local:
        def act(self, observation: dict, info: dict) -> np.ndarray:
            return np.zeros(3, dtype=np.float32)

    with pytest.raises(ValueError, match="does not pickle"):
        lanrocli.evaluate(Local(), "reach", episodes=2, workers=2)


def children(pid: int) -> set[int]:
    found = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout.split()
    return {int(child) for child in found}


def read(path: str) -> str:
    try:
        return Path(path).read_text(errors="ignore")
    except OSError:  # the process ended meanwhile
        return ""


def alive(pid: int) -> bool:
    """Running, not ended nor a zombie left to whoever adopted it."""
    stat = read(f"/proc/{pid}/stat")
    return bool(stat) and stat.rsplit(")", 1)[1].split()[0] != "Z"


def test_a_killed_scoring_leaves_no_worker_behind(tmp_path: Path) -> None:
    command = "from lanrocli.cli.app import app; app()"
    args = ["eval", "random", "--task", "reach", "--protocol", "test", "--workers", "2"]
    scoring = subprocess.Popen([sys.executable, "-c", command, *args], cwd=tmp_path, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    workers: set[int] = set()
    while time.monotonic() < deadline and len(workers) < 2:
        time.sleep(0.5)
        workers = {w for child in children(scoring.pid) for w in children(child) | {child}}
        workers = {w for w in workers if "spawn_main" in read(f"/proc/{w}/cmdline")}
    assert len(workers) >= 2, "the workers never started"
    scoring.kill()
    scoring.wait()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and any(alive(w) for w in workers):
        time.sleep(0.5)
    assert not any(alive(w) for w in workers)
