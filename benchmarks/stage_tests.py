"""The last stage's tests of a finished run, timed at two commits and over several worker counts: the
test, language check, correction test, splits and question test of the same checkpoints, as ``lanro train
--resume`` plays them after a run was stopped in its tests.

For each way, the run folder is copied, its last stage's ``test.json`` removed, and ``lanro train --out COPY
--resume`` run with that commit's code (the base in a temporary worktree). Prints each way's seconds, the
ratio to the base, and whether its ``test.json`` equals the base's. The ways run one after the other: two at
once would halve each other's speed.

    python benchmarks/stage_tests.py runs/push --base 495c8d4 --workers 1 2
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
COMMAND = [sys.executable, "-c", "from lanrocli.cli.app import app; app()", "train"]


def last_test(run: Path) -> Path:
    tests = sorted(run.glob("stage-*/test.json"))
    if not tests:
        raise SystemExit(f"{run} holds no tested stage: give a finished run folder")
    return tests[-1]


def timed(run: Path, copy: Path, tree: Path, options: list[str]) -> tuple[float, dict[str, Any]]:
    """Seconds that ``tree``'s code takes to test the last stage of a copy of ``run``, and its record."""
    shutil.copytree(run, copy)
    last_test(copy).unlink()
    started = time.perf_counter()
    subprocess.run(
        [*COMMAND, "--out", str(copy), "--resume", "--device", "cpu", *options],
        cwd=tree,
        env={**os.environ, "PYTHONPATH": str(tree)},
        check=True,
        stdout=subprocess.DEVNULL,
    )
    seconds = time.perf_counter() - started
    return seconds, json.loads(last_test(copy).read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="a finished run folder")
    parser.add_argument("--base", default="HEAD~1", help="the commit to compare with (its own way of testing)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="worker counts to test with here")
    args = parser.parse_args()
    last_test(args.run)
    with tempfile.TemporaryDirectory(prefix="stage-tests-") as scratch:
        tree = Path(scratch) / "base"
        subprocess.run(["git", "worktree", "add", "--detach", str(tree), args.base], cwd=ROOT, check=True)
        try:
            base_seconds, base_record = timed(args.run, Path(scratch) / "run-base", tree, [])
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)
        print(f"{args.base}: {base_seconds:.1f} s")
        for count in args.workers:
            seconds, record = timed(args.run, Path(scratch) / f"run-{count}", ROOT, ["--workers", str(count)])
            same = "the same test.json" if record == base_record else "a DIFFERENT test.json"
            print(f"HEAD, {count} worker(s): {seconds:.1f} s, {base_seconds / seconds:.2f}x; {same}")


if __name__ == "__main__":
    main()
