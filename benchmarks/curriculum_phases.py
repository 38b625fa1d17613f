"""A whole curriculum timed phase by phase, at two commits: where a change made a run faster or slower.

Each commit is checked out into a temporary worktree and trains the same curriculum and seed there, one
after the other (two at once would halve each other's speed), with its own code. The run folders' clocks
give, per stage, the seconds spent collecting, updating, evaluating, testing and on the rest; the table
shows both commits and the ratio, and the end-to-end wall time of each command.

    python benchmarks/curriculum_phases.py push                      # HEAD against HEAD~1
    python benchmarks/curriculum_phases.py quick --base 449f828 --json phases.json
    python benchmarks/curriculum_phases.py push --set 'stages[0].budget.steps=5000'

Both runs share the machine with whatever else runs: compare ratios measured in one session only.
"""

from __future__ import annotations

import argparse
import dataclasses
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
PHASES = ("collection", "updates", "evaluation", "tests", "rest", "total")


def commit(rev: str) -> str:
    return subprocess.run(
        ["git", "rev-parse", "--short", rev], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout.strip()


def train(rev: str, curriculum: str, seed: int, changes: list[str], scratch: Path) -> dict[str, Any]:
    """Train ``curriculum`` with the code of ``rev``; its wall time and per-stage phase seconds."""
    tree, out = scratch / f"tree-{rev}", scratch / f"run-{rev}"
    subprocess.run(["git", "worktree", "add", "--detach", str(tree), rev], cwd=ROOT, check=True, capture_output=True)
    try:
        command = [sys.executable, "-c", "from lanrocli.cli.app import app; app()", "train", curriculum]
        command += ["--out", str(out), "--seed", str(seed), "--device", "cpu"]
        command += ["--set", *changes] if changes else []
        started = time.perf_counter()
        subprocess.run(command, cwd=tree, env={**os.environ, "PYTHONPATH": str(tree)}, check=True)
        wall = time.perf_counter() - started
        return {"commit": rev, "wall_seconds": wall, "stages": stage_seconds(out)}
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)


def stage_seconds(out: Path) -> dict[str, dict[str, float | None] | None]:
    """Per stage of the finished run in ``out``: its phases' seconds, read by this checkout's code, which
    reads the run folders of earlier versions too. The last stage's checkpoint is written before its tests,
    so their time is not kept there: that stage's tests are None, and its total leaves them out."""
    from lanrocli.train.runfolder import LATEST, read_pointer
    from lanrocli.train.runstate import RunState

    saved = json.loads((read_pointer(out / LATEST) / "state.json").read_text())
    state = RunState.from_dict(saved["extra"]["run"])
    untested = {r.name for r in state.results if r.test_seconds is None}
    state.results = [
        r if r.test_seconds is not None else dataclasses.replace(r, test_seconds=0.0) for r in state.results
    ]
    found: dict[str, dict[str, float | None] | None] = {}
    for result in state.results:
        seconds: dict[str, float | None] | None = dict(state.seconds(result) or {}) or None
        if seconds is not None and result.name in untested:
            seconds["tests"] = None
        found[result.name] = seconds
    return found


def table(base: dict[str, Any], head: dict[str, Any]) -> list[str]:
    lines = [f"| stage | phase | {base['commit']}, s | {head['commit']}, s | ratio |", "|---|---|---|---|---|"]
    for stage in head["stages"]:
        then, now = base["stages"].get(stage), head["stages"][stage]
        for phase in PHASES:
            before, after = (None if found is None else found[phase] for found in (then, now))
            if before is None or after is None:
                lines.append(f"| {stage} | {phase} | - | - | - |")
                continue
            ratio = f"{after / before:.2f}" if before > 0 else "-"
            lines.append(f"| {stage} | {phase} | {before:.1f} | {after:.1f} | {ratio} |")
    wall = head["wall_seconds"] / base["wall_seconds"]
    lines.append(f"| whole command | wall | {base['wall_seconds']:.1f} | {head['wall_seconds']:.1f} | {wall:.2f} |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("curriculum", help="a packaged curriculum's name or a YAML file")
    parser.add_argument("--base", default="HEAD~1", help="the commit to compare against (default HEAD~1)")
    parser.add_argument("--head", default="HEAD", help="the commit measured (default HEAD)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--set", nargs="*", default=[], dest="changes", metavar="KEY=VALUE")
    parser.add_argument("--json", type=Path, help="also write both commits' figures here")
    args = parser.parse_args()
    curriculum = str(Path(args.curriculum).resolve()) if Path(args.curriculum).is_file() else args.curriculum
    scratch = Path(tempfile.mkdtemp(prefix="lanro-phases-"))
    try:
        base, head = (
            train(commit(rev), curriculum, args.seed, args.changes, scratch) for rev in (args.base, args.head)
        )
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    print("\n".join(table(base, head)))
    if args.json is not None:
        args.json.write_text(json.dumps({"base": base, "head": head}, indent=1) + "\n")


if __name__ == "__main__":
    main()
