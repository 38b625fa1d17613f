"""Environment steps per second, per task, with random actions (resets included).

For each task it reports the steps/s of ``LanroEnv`` and, from the same run, the time spent in the bare
``stepSimulation`` calls, so the overhead of everything else (IK, state queries, task conditions, the
instructor, the observation) is visible. With ``--reference-python`` pointing at an interpreter that has
the public ``lanro-gym`` 0.2.1 installed (it needs gymnasium < 1.0, so it lives in its own virtual
environment), the equivalent reference environment ``PandaNL<Task>2ShapeAR-v0`` is measured in the same
session, alternating rounds with ours, and the ratio is printed.

    python benchmarks/env_throughput.py --steps 3000 --rounds 3 --reference-python /tmp/refvenv/bin/python
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time

import numpy as np

from lanrocli.envs.env import LanroEnv
from lanrocli.tasks import TASKS

REFERENCE_SNIPPET = """
import sys, time, warnings
warnings.filterwarnings("ignore")
import gymnasium as gym, lanro_gym, numpy as np
env = gym.make(f"PandaNL{sys.argv[1].capitalize()}2ShapeAR-v0")
env.reset(seed=0)
env.action_space.seed(0)
steps = int(sys.argv[2])
start = time.perf_counter()
for _ in range(steps):
    _, _, terminated, truncated, _ = env.step(env.action_space.sample())
    if terminated or truncated:
        env.reset()
print(steps / (time.perf_counter() - start))
"""


def measure_ours(task: str, steps: int, seed: int) -> dict[str, float]:
    env = LanroEnv(task, objects=2, mode="shape", correction_rate=0.5)
    physics = 0.0
    bare_step = env.world.step_physics

    def timed_physics() -> None:
        nonlocal physics
        start = time.perf_counter()
        bare_step()
        physics += time.perf_counter() - start

    env.world.step_physics = timed_physics  # type: ignore[method-assign]
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, env.action_space.shape))
        if terminated or truncated:
            env.reset()
    total = time.perf_counter() - start
    env.close()
    return {"steps_per_s": steps / total, "physics_steps_per_s": steps / physics, "overhead": total / physics - 1}


def measure_reference(python: str, task: str, steps: int) -> float:
    out = subprocess.run(
        [python, "-c", REFERENCE_SNIPPET, task, str(steps)], capture_output=True, text=True, check=True
    )
    return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=2000, help="environment steps per task and round")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds; the median is reported")
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS)
    parser.add_argument("--reference-python", help="python of a virtual environment with lanro-gym 0.2.1")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()

    results: dict[str, dict[str, float]] = {}
    for task in args.tasks:
        ours, reference = [], []
        for round_ in range(args.rounds):
            ours.append(measure_ours(task, args.steps, seed=round_))
            if args.reference_python:
                reference.append(measure_reference(args.reference_python, task, args.steps))
        row = {key: statistics.median(r[key] for r in ours) for key in ours[0]}
        if reference:
            row["reference_steps_per_s"] = statistics.median(reference)
            row["ratio"] = row["steps_per_s"] / row["reference_steps_per_s"]
        results[task] = row

    if args.json:
        print(json.dumps({"steps": args.steps, "rounds": args.rounds, "tasks": results}))
        return
    print(f"{'task':<7}{'lanro steps/s':>15}{'bare physics':>15}{'overhead':>10}{'lanro-gym':>12}{'ratio':>8}")
    for task, row in results.items():
        ref = f"{row['reference_steps_per_s']:12.0f}{row['ratio']:8.2f}" if "ratio" in row else ""
        print(
            f"{task:<7}{row['steps_per_s']:15.0f}{row['physics_steps_per_s']:15.0f}{100 * row['overhead']:9.1f}%{ref}"
        )


if __name__ == "__main__":
    sys.exit(main())
