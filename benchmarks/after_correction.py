"""What a trained agent does once a correction is spoken: the part of a correction episode that decides it.

Runs a checkpoint's deterministic policy on correction episodes (from the neutral start, like evaluation)
and sorts every episode in which the instructor spoke into:

- *succeeded*: the arm then did the task on the goal object;
- *knocked the goal* / *knocked another*: it failed, and that object ended up farther from its start than
  reach allows (2.5 cm), which leaves a reach episode unsolvable; *fell*: an object went off the table;
- *fell short*: it failed without disturbing anything; the closest the end effector came to the goal
  object after the correction is reported (median), to tell "went elsewhere" from "stopped near".

    python benchmarks/after_correction.py runs/learning-corrections --episodes 100

The episodes use seeds ``--seed`` onwards, the checkpoint's task and object count, and the kinds of
misunderstanding named by ``--kinds`` (default: the two in which the arm must first touch a wrong object).
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

import numpy as np
import torch

from lanrocli.envs import LanroEnv
from lanrocli.envs.env import FALLEN
from lanrocli.envs.evaluation import evaluation_settings
from lanrocli.envs.tasks import REACH_STILL
from lanrocli.train.trainer import AgentPolicy, load_policy


def run(env: LanroEnv, policy: AgentPolicy, seed: int) -> tuple[str, float] | None:
    """The outcome of one episode after its correction, and the closest approach to the goal after it."""
    obs, info = env.reset(seed=seed)
    start = info["object_positions"]
    closest = np.inf
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        done = terminated or truncated
        if info["correction"] is not None:
            hand = obs["observation"][:3]
            closest = min(closest, float(np.linalg.norm(info["object_positions"][info["goal_index"]] - hand)))
    if info["correction"] is None:
        return None
    if terminated:
        return "succeeded", closest
    positions = info["object_positions"]
    if np.any(positions[:, 2] < FALLEN):
        return "fell", closest
    knocked = np.linalg.norm(positions - start, axis=1) > REACH_STILL
    if knocked[info["goal_index"]]:
        return "knocked the goal", closest
    if np.any(knocked):
        return "knocked another", closest
    return "fell short", closest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkpoint", type=Path, help="checkpoint, pointer file or run folder")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--kinds", nargs="+", default=["ambiguity", "instruction_correction"])
    args = parser.parse_args()
    torch.set_num_threads(1)
    settings, policy = load_policy(args.checkpoint)
    env_settings = {**evaluation_settings(settings.env), "correction_rate": 1.0, "kinds": args.kinds}
    env = LanroEnv(settings.task, object_slots=settings.slots, **env_settings)
    outcomes = [run(env, policy, args.seed + i) for i in range(args.episodes)]
    env.close()
    spoken = [o for o in outcomes if o is not None]
    counts = Counter(kind for kind, _ in spoken)
    print(f"{args.checkpoint}: {settings.task}, kinds {', '.join(args.kinds)}, seeds {args.seed}..")
    print(f"{args.episodes} episodes, a correction was spoken in {len(spoken)}")
    for kind in ("succeeded", "knocked the goal", "knocked another", "fell", "fell short"):
        near = [c for k, c in spoken if k == kind and np.isfinite(c)]
        median = f", closest approach to the goal after it: median {np.median(near) * 100:.1f} cm" if near else ""
        print(f"  {kind:<16} {counts[kind]:>4}{median}")


if __name__ == "__main__":
    main()
