"""Evaluation throughput: a trained agent's test episodes played the ways lanro has played them, in
alternating rounds, environment steps per second and the ratios to the first way:

- ``side by side, environments in workers``: ``SIDE_BY_SIDE`` episodes at a time, the policy answering them in
  this process and each environment stepping in a process of its own (how a run's tests were played before
  they were cut into blocks, and how training's evaluations still are);
- ``blocks over N workers``: each worker plays blocks of episodes, policy and environments in one process
  (:mod:`lanrocli.evaluation.blocks`, how runs and ``lanro eval`` measure now). The workers are started and
  started before the clock starts; what starting them costs is printed apart.

Every way gives the same outcomes (the batches are padded to one size), which the script checks.

    python benchmarks/evaluation_throughput.py --episodes 200 --rounds 3 --workers 1 2    # the shipped push agent
    python benchmarks/evaluation_throughput.py runs/push-s0 --correction-episodes --workers 1 2 4 8 16
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
from lanrocli.evaluation.blocks import CHUNK, Workers, play
from lanrocli.evaluation.evaluate import SIDE_BY_SIDE, EvaluationReport, evaluate
from lanrocli.pretrained import agent_path
from lanrocli.train.trainer import load_policy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("agent", nargs="?", default="push", help="a checkpoint, run folder or shipped agent's name")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="worker counts to play blocks with")
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
    in_workers = make_envs(make, SIDE_BY_SIDE, in_workers=True)
    pools = {count: Workers(count) for count in args.workers}
    ways = {"side by side, environments in workers": functools.partial(evaluate, in_workers, policy)}
    for count, pool in pools.items():
        source = pool.source(policy)
        started = time.perf_counter()
        play(pool, source, make, 2 * count * CHUNK, first)  # starts every worker
        print(f"starting {count} worker(s): {time.perf_counter() - started:.1f} s")
        ways[f"blocks over {count} worker(s)"] = functools.partial(play, pool, source, make)

    rates: dict[str, list[float]] = {way: [] for way in ways}
    reports: dict[str, EvaluationReport] = {}
    try:
        for _ in range(args.rounds):
            for way, played in ways.items():
                start = time.perf_counter()
                reports[way] = report = played(args.episodes, first)
                rates[way].append(sum(r.length for r in report.results) / (time.perf_counter() - start))
    finally:
        for env in in_workers:
            env.close()
        for pool in pools.values():
            pool.close()

    base = next(iter(ways))
    for way in ways:
        line = f"{way}: {statistics.median(rates[way]):.0f} env steps/s"
        if way != base:
            ratios = ", ".join(f"{b / a:.2f}x" for a, b in zip(rates[base], rates[way]))
            line += f", {statistics.median(rates[way]) / statistics.median(rates[base]):.2f}x (rounds: {ratios})"
        same = reports[way].results == reports[base].results
        print(f"{line}; success {reports[way].overall.value:.3f}; outcomes {'the same' if same else 'DIFFERENT'}")


if __name__ == "__main__":
    main()
