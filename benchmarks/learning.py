"""Learning speed: train reach with 2 objects (colour mode) from scratch and write success vs environment
steps to CSV; the second setting adds correction episodes (``correction_rate=0.5``).

    python benchmarks/learning.py plain --steps 300000 --out runs/learning-plain
    python benchmarks/learning.py corrections --steps 1000000 --out runs/learning-corrections

The CSV (``metrics.csv`` in ``--out``) gets one row per evaluation: environment steps, wall time, success on
fixed evaluation episodes (deterministic policy), success on correction episodes, losses. The run is
checkpointed at every evaluation and continues with ``--resume`` after a crash or kill.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from lanrocli.agent import SACSettings
from lanrocli.train import Trainer, TrainSettings, pick_device

SETTINGS = {
    "plain": {"objects": 2, "mode": "color", "correction_rate": 0.0},
    "corrections": {"objects": 2, "mode": "color", "correction_rate": 0.5},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("setting", choices=sorted(SETTINGS))
    parser.add_argument("--steps", type=int, default=300_000)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--eval-every", type=int, default=10_000)
    parser.add_argument("--eval-episodes", type=int, default=50)
    parser.add_argument("--target", type=float, help="stop once evaluation success reaches this")
    parser.add_argument("--device", choices=["cpu", "cuda"], help="default: cuda if available, else cpu")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    device = pick_device(args.device)

    if args.resume:
        trainer = Trainer.resume(args.out, device)
    else:
        settings = TrainSettings(
            task="reach",
            env=SETTINGS[args.setting],
            seed=args.seed,
            envs=args.envs,
            eval_every=args.eval_every,
            eval_episodes=args.eval_episodes,
        )
        trainer = Trainer(settings, SACSettings(), args.out, device)

    def report(t: Trainer, evaluation) -> None:  # type: ignore[no-untyped-def]
        corrections = evaluation.corrections
        extra = f", corrections {corrections.success:.2f}" if corrections.episodes else ""
        print(f"{t.progress.env_steps} steps, {t.wall_time():.0f} s: success {evaluation.overall.success:.2f}{extra}", flush=True)
        if args.target is not None:
            key = evaluation.corrections if args.setting == "corrections" else evaluation.overall
            if key.episodes and key.success >= args.target:
                reached.append(t.progress.env_steps)

    reached: list[int] = []
    trainer.run(args.steps, should_stop=lambda: bool(reached), on_evaluation=report)
    trainer.close()
    if reached:
        print(f"target reached at {reached[0]} environment steps")


if __name__ == "__main__":
    main()
