"""Trainings side by side: the environment steps per second of one training alone against those of several
trainings run at once on the same machine, each in a process of its own (as a sweep's trials are).

A training learns with one torch thread, and its environment workers spend most of their time waiting for
the next action, so a training keeps about one core busy, not one per process. This measures what that means
for a sweep of seeds: how many trainings a machine holds before each slows down. Each training is that of
``train_throughput.py`` (reach with two objects in two environment workers, a curriculum's agent and
buffer), on a seed of its own. The counts given alternate, round after round, so a shared machine's drift
hits every count alike; the medians are reported.

    python benchmarks/side_by_side.py --curriculum reach --trainings 1 2 3 --steps 2000 --rounds 3
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import statistics

import torch
from train_throughput import run_ours

from lanrocli.agent.settings import BufferSettings, SACSettings
from lanrocli.config.curriculum import find_curriculum, load_curriculum


def one_training(
    steps: int, seed: int, agent: SACSettings, buffer: BufferSettings, results: multiprocessing.Queue
) -> None:
    torch.set_num_threads(1)
    results.put(run_ours(steps, 2, 500, seed, agent, buffer, "cpu")["env_steps_per_s"])


def side_by_side(count: int, steps: int, agent: SACSettings, buffer: BufferSettings) -> dict[str, float]:
    """``count`` trainings started together; each one's environment steps per second (counted as
    ``train_throughput.py`` counts them, the steps before the first update included), and their sum, the
    machine's throughput."""
    context = multiprocessing.get_context("spawn")  # fresh interpreters, as a sweep's trial processes are
    results: multiprocessing.Queue = context.Queue()
    processes = [
        context.Process(target=one_training, args=(steps, seed, agent, buffer, results)) for seed in range(count)
    ]
    for process in processes:
        process.start()
    each = [results.get() for _ in processes]
    for process in processes:
        process.join()
    return {"total_env_steps_per_s": sum(each), "slowest_env_steps_per_s": min(each)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--curriculum", default="reach", help="whose agent and buffer (a packaged name or a file)")
    parser.add_argument("--trainings", type=int, nargs="+", default=[1, 2], help="how many at once, each in turn")
    parser.add_argument("--steps", type=int, default=2000, help="environment steps of each training")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.rounds < 1 or min(args.trainings) < 1:
        parser.error("--rounds and every --trainings must be at least 1")
    if 1 not in args.trainings:
        parser.error("--trainings must include 1: one training alone is what the others are measured against")
    curriculum = load_curriculum(find_curriculum(args.curriculum))
    agent, buffer = curriculum.agent.settings(), curriculum.buffer.settings()
    rounds: dict[int, list[dict[str, float]]] = {count: [] for count in args.trainings}
    for _ in range(args.rounds):
        for count in args.trainings:
            rounds[count].append(side_by_side(count, args.steps, agent, buffer))
    alone = statistics.median(r["total_env_steps_per_s"] for r in rounds[1])
    summary = []
    for count, results in rounds.items():
        total = statistics.median(r["total_env_steps_per_s"] for r in results)
        summary.append(
            {
                "trainings": count,
                "total_env_steps_per_s": total,
                "each_env_steps_per_s": total / count,
                "slowest_env_steps_per_s": statistics.median(r["slowest_env_steps_per_s"] for r in results),
                "throughput_against_one": total / alone,
                "rounds": [r["total_env_steps_per_s"] for r in results],
            }
        )
    if args.json:
        print(json.dumps(summary))
        return
    for row in summary:
        rounds_text = ", ".join(f"{value:.0f}" for value in row["rounds"])
        print(
            f"{row['trainings']} at once: {row['total_env_steps_per_s']:.0f} env steps/s in all "
            f"({row['each_env_steps_per_s']:.0f} each, slowest {row['slowest_env_steps_per_s']:.0f}; "
            f"{row['throughput_against_one']:.2f}x one alone; rounds {rounds_text})"
        )


if __name__ == "__main__":
    main()
