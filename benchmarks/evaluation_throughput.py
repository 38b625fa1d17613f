"""Evaluation throughput: a trained agent's test episodes one after another against ``SIDE_BY_SIDE`` at a
time (the way runs and ``lanro eval`` play them), alternating rounds, with the environments built before
the clock starts. Prints environment steps per second of each, the ratio, and in how many episodes the two
disagree: a batch rounds the network's arithmetic differently in the last bit, which changes the outcome of
an occasional episode (a scripted policy gives identical results; ``tests/envs/test_rollout.py``).

    python benchmarks/evaluation_throughput.py --episodes 100 --rounds 3          # the shipped push agent
    python benchmarks/evaluation_throughput.py runs/push-s0 --correction-episodes  # any checkpoint
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import torch

from lanrocli.envs.env import LanroEnv
from lanrocli.envs.evaluation import SIDE_BY_SIDE, EvaluationReport, evaluate
from lanrocli.train.pretrained import agent_path
from lanrocli.train.seeds import held_out_seed
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

    def make() -> LanroEnv:
        return LanroEnv(
            settings.task, env_settings, object_slots=settings.slots, vocabulary=policy.vocabulary, holdout=settings.holdout
        )

    first = held_out_seed(settings.seed, settings.stage)
    alone, together = [make()], [make() for _ in range(SIDE_BY_SIDE)]
    rates: dict[int, list[float]] = {1: [], SIDE_BY_SIDE: []}
    reports: dict[int, EvaluationReport] = {}
    for _ in range(args.rounds):
        for envs in (alone, together):
            start = time.perf_counter()
            reports[len(envs)] = report = evaluate(envs, policy, args.episodes, first)
            rates[len(envs)].append(sum(r.length for r in report.results) / (time.perf_counter() - start))
    for env in [*alone, *together]:
        env.close()

    one, many = (statistics.median(rates[n]) for n in (1, SIDE_BY_SIDE))
    print(f"one after another: {one:.0f} env steps/s; {SIDE_BY_SIDE} side by side: {many:.0f} env steps/s")
    print(f"ratio: {many / one:.2f}x (rounds: {', '.join(f'{b / a:.2f}x' for a, b in zip(rates[1], rates[SIDE_BY_SIDE]))})")
    a, b = reports[1], reports[SIDE_BY_SIDE]
    differing = sum(x.success != y.success for x, y in zip(a.results, b.results))
    print(f"success {a.overall.value:.3f} against {b.overall.value:.3f}; outcomes differ in {differing} of {args.episodes}")


if __name__ == "__main__":
    main()
