"""lanro on a machine without a C++ compiler: a quick training run that asks for a compiled update, in a process
whose ``PATH`` finds a ``cc``, ``c++``, ``gcc`` and ``g++`` that all fail. A user's machine may have none, and
torch.compile then cannot build its kernels: the agent must fall back to eager PyTorch rather than fail, and
only a run on such a machine shows it, as this one has a compiler."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.train.runs import tiny

ROOT = Path(__file__).resolve().parents[1]
COMPILERS = ("cc", "c++", "gcc", "g++")


@pytest.fixture
def no_compiler(tmp_path: Path) -> dict[str, str]:
    """An environment in which every C++ compiler fails, and with empty build caches, so that nothing built
    earlier with a working compiler is reused; this checkout first on the import path."""
    fake = tmp_path / "compilers"
    fake.mkdir()
    for name in COMPILERS:
        script = fake / name
        script.write_text("#!/bin/sh\nexit 1\n")
        script.chmod(0o755)
    caches = tmp_path / "caches"
    env = {key: value for key, value in os.environ.items() if key not in ("CC", "CXX")}
    env |= {
        "PATH": f"{fake}{os.pathsep}{os.environ['PATH']}",
        "PYTHONPATH": str(ROOT),
        "TORCHINDUCTOR_CACHE_DIR": str(caches / "inductor"),
        "TORCH_EXTENSIONS_DIR": str(caches / "extensions"),
        "TRITON_CACHE_DIR": str(caches / "triton"),
    }
    assert all(shutil.which(name, path=env["PATH"]) == str(fake / name) for name in COMPILERS)
    return env


def run(command: list[str], cwd: Path, env: dict[str, str]) -> str:
    """``command``'s output; fails with it unless the command succeeds."""
    result = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=1200, check=False)
    assert result.returncode == 0, f"{command}:\n{result.stdout}\n{result.stderr}"
    return result.stdout + result.stderr


@pytest.mark.slow
def test_a_training_asking_for_a_compiled_update_runs_eager_without_a_compiler(
    no_compiler: dict[str, str], tmp_path: Path
) -> None:
    """The tiny curriculum of the run tests, its update asked to compile: torch.compile cannot build its
    kernels here, so the run must say so and train eagerly to the end, tests included."""
    out = tmp_path / "run"
    command = [sys.executable, "-c", "from lanrocli.cli.app import app; app()", "train", str(tiny(tmp_path))]
    output = run([*command, "--out", str(out), "--set", "agent.compile=true"], tmp_path, no_compiler)
    assert "torch.compile failed here, the update runs eager" in output
    assert list(out.glob("stage-*/test.json")), "the run saved no stage's test results"
