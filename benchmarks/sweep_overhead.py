"""What running a curriculum as a one-trial sweep costs over ``lanro train``: starting a local Ray instance,
Tune's trial machinery, the trial's worker process, progress reports, and stopping Ray again.

Each round runs ``lanro train CURRICULUM --seed S`` and ``lanro sweep CURRICULUM --seeds S`` back to back as
whole commands (wall time from start to exit, Python's start-up and imports included), alternating which goes
first, so that a shared machine's drift hits both alike; the median of the rounds' ratios is reported. Both
train the same curriculum, resolved once and written to a file, on the same seed, so they do the same work;
the check that their metrics agree is printed too.

    python benchmarks/sweep_overhead.py --quick --rounds 3          # the built-in curriculum
    python benchmarks/sweep_overhead.py curricula/push.yaml --quick
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from lanrocli.config.curriculum import builtin_curriculum, load_curriculum


def timed(args: list[str], cwd: Path) -> float:
    start = time.perf_counter()
    result = subprocess.run(
        [sys.executable, "-c", "from lanrocli.cli.app import app; app()", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
    )
    seconds = time.perf_counter() - start
    if result.returncode != 0:
        raise SystemExit(f"lanro {' '.join(args)} failed:\n{result.stdout}\n{result.stderr}")
    return seconds


def metrics(run: Path) -> list[dict[str, str]]:
    with open(run / "metrics.csv", newline="") as f:
        return [{k: v for k, v in row.items() if k != "wall_time"} for row in csv.DictReader(f)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("curriculum", nargs="?", help="curriculum file (default: the built-in one, with --quick)")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rounds", type=int, default=3)
    options = parser.parse_args()
    plan = load_curriculum(options.curriculum) if options.curriculum else builtin_curriculum()
    if options.quick and options.curriculum:
        plan = plan.quick()
    rounds = []
    with tempfile.TemporaryDirectory() as folder:
        cwd = Path(folder)
        # The plan resolved once, as a file: both commands of every round train exactly this.
        source = cwd / "curriculum.yaml"
        source.write_text(plan.to_yaml())
        for number in range(options.rounds):
            train = ["train", str(source), "--seed", str(options.seed), "--out", f"train-{number}"]
            sweep = ["sweep", str(source), "--seeds", str(options.seed), "--out", f"sweep-{number}"]
            order = [("train", train), ("sweep", sweep)]
            times = {name: timed(args, cwd) for name, args in (order if number % 2 == 0 else order[::-1])}
            same = metrics(cwd / f"train-{number}") == metrics(cwd / f"sweep-{number}" / f"seed={options.seed}")
            rounds.append({**times, "ratio": times["sweep"] / times["train"], "same_metrics": same})
            print(json.dumps({"round": number + 1, **rounds[-1]}), flush=True)
    print(
        json.dumps(
            {
                "curriculum": options.curriculum or "built-in",
                "name": plan.name,
                "quick": options.quick,
                "rounds": len(rounds),
                "train_s": [round(r["train"], 1) for r in rounds],
                "sweep_s": [round(r["sweep"], 1) for r in rounds],
                "median_ratio": round(statistics.median(r["ratio"] for r in rounds), 3),
                "same_metrics": all(r["same_metrics"] for r in rounds),
            }
        )
    )


if __name__ == "__main__":
    main()
