"""Evaluation throughput: a trained agent's test episodes one after another, ``SIDE_BY_SIDE`` at a time in
this process, and ``SIDE_BY_SIDE`` at a time each in a worker process (the way runs and ``lanro eval``
play them), alternating rounds, with the environments built before the clock starts. Prints environment
steps per second of each, the ratios to one after another, and in how many episodes they disagree: a batch
rounds the network's arithmetic differently in the last bit, which changes the outcome of an occasional
episode (a scripted policy gives identical results; ``tests/envs/test_rollout.py``). Side by side in this
process and in workers, the agent sees the same batches, so those two agree exactly.

    python benchmarks/evaluation_throughput.py --episodes 100 --rounds 3          # the shipped push agent
    python benchmarks/evaluation_throughput.py runs/push-s0 --correction-episodes  # any checkpoint
"""

from __future__ import annotations

import argparse
import functools
import statistics
import time
from pathlib import Path

import torch

from lanrocli.core.seeds import held_out_seed
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.workers import make_envs
from lanrocli.evaluation.evaluate import SIDE_BY_SIDE, EvaluationReport, evaluate
from lanrocli.pretrained import agent_path
from lanrocli.train.trainer import load_policy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("agent", nargs="?", default="push", help="a checkpoint, run folder or shipped agent's name")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--correction-episodes", action="store_true", help="every episode a correction episode")
    args = parser.parse_args()
    torch.set_num_threads(1)  # as lanro train and lanro eval run on CPU

    settings, policy = load_policy(agent_path(Path(args.agent)))
    env_settings = settings.env.for_evaluation()
    if args.correction_episodes:
        env_settings = env_settings.replace(correction_rate=1.0)

    make = functools.partial(
        LanroEnv,
        settings.task,
        env_settings,
        object_slots=settings.slots,
        vocabulary=policy.vocabulary,
        holdout=settings.holdout,
    )
    first = held_out_seed(settings.seed, settings.stage)
    ways = {
        "one after another": make_envs(make, 1, in_workers=False),
        f"{SIDE_BY_SIDE} side by side": make_envs(make, SIDE_BY_SIDE, in_workers=False),
        f"{SIDE_BY_SIDE} side by side in workers": make_envs(make, SIDE_BY_SIDE, in_workers=True),
    }
    rates: dict[str, list[float]] = {way: [] for way in ways}
    reports: dict[str, EvaluationReport] = {}
    for _ in range(args.rounds):
        for way, envs in ways.items():
            start = time.perf_counter()
            reports[way] = report = evaluate(envs, policy, args.episodes, first)
            rates[way].append(sum(r.length for r in report.results) / (time.perf_counter() - start))
    for env in [env for envs in ways.values() for env in envs]:
        env.close()

    base = next(iter(ways))
    for way in ways:
        ratios = ", ".join(f"{b / a:.2f}x" for a, b in zip(rates[base], rates[way]))
        line = f"{way}: {statistics.median(rates[way]):.0f} env steps/s"
        if way != base:
            line += f", {statistics.median(rates[way]) / statistics.median(rates[base]):.2f}x (rounds: {ratios})"
        differing = sum(x.success != y.success for x, y in zip(reports[base].results, reports[way].results))
        print(
            f"{line}; success {reports[way].overall.value:.3f}, outcomes differing from one after another: {differing}"
        )


if __name__ == "__main__":
    main()
