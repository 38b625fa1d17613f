"""The package as a user installs it: a wheel built from the source, installed into a fresh environment, runs
``lanro`` from a directory outside the repository with only what the wheel ships."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ["pyproject.toml", "README.md", "LICENSE", "lanrocli"]
"""What a build reads: the package and the files its metadata names."""
SHIPPED = [
    "lanrocli/py.typed",
    "lanrocli/language/word_ids.txt",
    "lanrocli/curricula/push.yaml",
    *(f"lanrocli/pretrained/push/{name}" for name in ("agent.pt", "state.json", "manifest.json")),
]


def run(command: list[str | Path], cwd: Path, lines: str | None = None) -> str:
    """``command`` without this checkout on the path, so that nothing is imported from it, reading ``lines``;
    its output."""
    env = {key: value for key, value in os.environ.items() if key != "PYTHONPATH"}
    result = subprocess.run(
        [str(part) for part in command],
        cwd=cwd,
        env=env,
        input=lines,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert result.returncode == 0, f"{command}:\n{result.stdout}\n{result.stderr}"
    return result.stdout + result.stderr


@pytest.mark.slow
def test_the_wheel_installs_and_runs_a_packaged_curriculum_and_agent_from_anywhere(tmp_path: Path) -> None:
    source = tmp_path / "source"  # a copy, as a build writes into the tree it builds
    source.mkdir()
    for name in SOURCE:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy(ROOT / name, source / name)
    built = run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-v", "-w", tmp_path / "dist", source], tmp_path)
    assert not re.search(r"Setuptools\w*Warning", built), built
    (wheel,) = (tmp_path / "dist").glob("lanro-*.whl")
    assert set(SHIPPED) <= set(zipfile.ZipFile(wheel).namelist())

    # A fresh environment that sees this one's packages (torch among them) behind its own, so that installing
    # downloads nothing: --no-index refuses to.
    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", venv], tmp_path)
    python = venv / "bin" / "python"
    own = run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], tmp_path).strip()
    paths = dict.fromkeys(sysconfig.get_paths()[key] for key in ("purelib", "platlib"))
    Path(own, "lanro-test-dependencies.pth").write_text("".join(f"{path}\n" for path in paths))
    run([python, "-m", "pip", "install", "--no-index", "--no-deps", "--force-reinstall", wheel], tmp_path)

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    imported = run([python, "-c", "import lanrocli; print(lanrocli.__file__)"], elsewhere)
    assert Path(imported.strip()).is_relative_to(venv), imported
    checked = run([venv / "bin" / "lanro", "check", "push"], elsewhere)
    assert "push: push" in checked and "environment steps in all" in checked
    played = run([venv / "bin" / "lanro", "play", "push", "--episodes", "1"], elsewhere, "push the red object\n")
    assert "episode 1:" in played and "1 episode" in played  # the shipped agent, from the wheel
