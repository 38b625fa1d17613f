"""Learning speed: train reach with 2 objects (colour mode) from scratch and write success against
environment steps to CSV; the second setting adds correction episodes (``correction_rate=0.5``).

    python benchmarks/learning.py plain --steps 300000 --out runs/learning-plain
    python benchmarks/learning.py corrections --steps 1000000 --out runs/learning-corrections

Each setting is a one-stage curriculum run by the same pipeline as ``lanro train``, so ``--out`` is a run
folder: ``metrics.csv`` gets one row per evaluation (environment steps, wall time, success on fresh
evaluation episodes with the deterministic policy, success where a correction was spoken, losses), ``lanro plot``
draws it, and ``--resume`` continues it after a crash or kill. ``--target`` ends the run once the
pooled evaluation success (where a correction was spoken, for the second setting) reaches it. ``--random-start P``
starts that share of the training episodes with the hand at a random point near the table (evaluation
always starts from the neutral pose).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import torch

from lanrocli.agent.settings import SACSettings
from lanrocli.config.curriculum import Curriculum
from lanrocli.train.pipeline import CurriculumRun, RunObserver
from lanrocli.train.stop import StopRequest
from lanrocli.train.trainer import pick_device

AGENT = {"architecture": "objects"}
"""The agent as the shipped curricula configure it; ``--agent`` changes any setting (``architecture=flat``
for the paper's network)."""

SETTINGS = {
    "plain": {"objects": 2, "mode": "colour", "correction_rate": 0.0},
    "corrections": {"objects": 2, "mode": "colour", "correction_rate": 0.5},
}


def curriculum(
    setting: str,
    steps: int,
    seed: int,
    envs: int,
    every: int,
    episodes: int,
    target: float | None,
    agent: dict[str, Any],
    random_start: float = 0.0,
) -> Curriculum:
    env = {**SETTINGS[setting], "random_start": random_start}
    stage: dict[str, Any] = {"name": setting, "env": env, "budget": {"steps": steps}}
    if target is not None:
        stage["promote"] = {"success": target, "on": "corrected" if setting == "corrections" else "overall"}
    return Curriculum.model_validate(
        {
            "name": f"learning-{setting}",
            "task": "reach",
            "seed": seed,
            "envs": envs,
            "agent": agent,
            "eval": {"every": every, "episodes": episodes},
            "stages": [stage],
        }
    )


def agent_overrides(pairs: list[str]) -> dict[str, str]:
    """``NAME=VALUE`` pairs; the curriculum's validation converts and checks the values."""
    known = SACSettings().to_dict()
    overrides = {}
    for pair in pairs:
        name, _, value = pair.partition("=")
        if name not in known:
            raise SystemExit(f"--agent: unknown setting {name!r}; known: {', '.join(sorted(known))}")
        overrides[name] = value
    return overrides


class Printer(RunObserver):
    def on_evaluation(self, run: CurriculumRun, row: dict[str, Any]) -> None:
        extra = f", corrected {row['corrected_success']:.2f}" if row["corrected_success"] != "" else ""
        print(f"{row['env_steps']} steps, {row['wall_time']:.0f} s: success {row['success']:.2f}{extra}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("setting", choices=sorted(SETTINGS))
    parser.add_argument("--steps", type=int, default=300_000)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--eval-every", type=int, default=10_000)
    parser.add_argument("--eval-episodes", type=int, default=100)
    parser.add_argument("--target", type=float, help="stop once evaluation success reaches this")
    parser.add_argument(
        "--random-start",
        type=float,
        default=0.0,
        metavar="P",
        help="share of training episodes that start with the hand at a random point near the table",
    )
    parser.add_argument("--device", choices=["cpu", "cuda"], help="default: cuda if available, else cpu")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out")
    parser.add_argument(
        "--agent",
        nargs="*",
        default=[],
        metavar="NAME=VALUE",
        help="agent settings, e.g. critics=2 (default: the paper's, read object by object)",
    )
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    device = pick_device(args.device)
    plan = curriculum(
        args.setting,
        args.steps,
        args.seed,
        args.envs,
        args.eval_every,
        args.eval_episodes,
        args.target,
        {**AGENT, **agent_overrides(args.agent)},
        args.random_start,
    )
    if args.resume:
        run = CurriculumRun.resume(args.out, plan, device, Printer())
    else:
        run = CurriculumRun.start(plan, args.out, device, Printer())
    with StopRequest() as stop:
        try:
            finished = run.run(should_stop=stop.requested)
        finally:
            run.close()
    if not finished:
        print(
            f"stopped at {run.trainer.progress.env_steps} environment steps; checkpoint written. "
            "Continue with the same arguments plus --resume."
        )
        raise SystemExit(130)
    result = run.state.results[-1]
    if result.ended == "promoted":
        print(f"target reached at {result.end} environment steps, {result.wall_time:.0f} s")


if __name__ == "__main__":
    main()
