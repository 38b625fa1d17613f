"""A training's loop with its replayed update on one thread and on two (``SACAgent.update_threads``), in
alternating rounds in one process: ``train_throughput.py``'s loop (reach.yaml's agent and buffer, two
environments in subprocesses, one update per environment step), whose environment workers simulate while the
update runs. On a machine without a core beyond the training's thread and its workers the helper competes with
the simulation, which is why a training takes it only where there is one (``replay.update_threads``).

    python benchmarks/update_threads.py --steps 2000 --rounds 3
"""

from __future__ import annotations

import argparse
import statistics

import torch
from train_throughput import run_ours

from lanrocli.config.curriculum import find_curriculum, load_curriculum


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--curriculum", default="reach", help="whose agent and buffer (a packaged name or a file)")
    args = parser.parse_args()
    torch.set_num_threads(1)  # as lanro train on CPU
    curriculum = load_curriculum(find_curriculum(args.curriculum))
    agent, buffer = curriculum.agent.settings(), curriculum.buffer.settings()
    rates: dict[int, list[float]] = {1: [], 2: []}
    for round_ in range(1, args.rounds + 1):
        for threads, measured in rates.items():
            result = run_ours(args.steps, args.envs, 500, 0, agent, buffer, "cpu", update_threads=threads)
            measured.append(result["env_steps_per_s"])
        print(f"round {round_}: " + ", ".join(f"{t} thread(s) {r[-1]:.0f}" for t, r in rates.items()) + " env steps/s", flush=True)
    one, two = (statistics.median(rates[t]) for t in (1, 2))
    print(f"median env steps/s: one thread {one:.0f}, two threads {two:.0f}; two against one {two / one:.2f}x")


if __name__ == "__main__":
    main()
