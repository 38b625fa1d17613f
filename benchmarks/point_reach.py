"""The agent alone, without physics: a point-mass version of reach, for checking what the learner can do.

A point (the "hand") starts 10 cm above a table and moves by up to 4 cm per axis and step; 1 to 3 cubes of
different colours lie in a 30 x 30 cm area. The instruction names one by colour ("reach the red cube"),
and touching means coming within ``--radius`` of its centre. Observations have the environment's layout
(arm 7 numbers, then 31 per object: position, offset from the hand, displacement, orientation,
velocities, one-hot colour and shape), and the same agent, replay buffer and hindsight relabelling learn
from them, with one update per step after 1000 random steps.

An episode takes microseconds instead of PyBullet's milliseconds, so in minutes it tells whether a change
to the agent helps it choose the named object at all:

    python benchmarks/point_reach.py --steps 40000 --objects 2 --agent architecture=flat
    python benchmarks/point_reach.py --steps 40000 --objects 2 --agent architecture=objects

Every 5000 steps it prints (and with ``--out`` appends to a CSV) the training success over the last 50
episodes and the deterministic policy's success on 30 fixed episodes.
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np
import torch
from learning import AGENT, agent_overrides  # this directory's learning benchmark: same agent, same --agent parsing
from pydantic import ValidationError

from lanrocli.agent.buffer.replay_buffer import ReplayBuffer
from lanrocli.agent.buffer.transitions import EpisodeData
from lanrocli.agent.networks import ObjectLayout
from lanrocli.agent.sac import SACAgent
from lanrocli.agent.settings import BufferSettings
from lanrocli.config.sections import AgentConfig
from lanrocli.envs.env import ARM_SIZE, OBJECT_SIZE
from lanrocli.language import COLOURS, SHAPES, ObjectProps, grammar_vocabulary

VOCABULARY = grammar_vocabulary()
START = np.array([0.0, 0.0, 0.10])
LOW, HIGH = np.array([-0.22, -0.22, 0.015]), np.array([0.22, 0.22, 0.20])
STEP = 0.04
HEIGHT = 0.05
LIMIT = 50
RANDOM_STEPS = 1000
EVAL_EVERY = 5000
EVAL_EPISODES = 30


def observe(hand: np.ndarray, positions: np.ndarray, colours: np.ndarray) -> np.ndarray:
    """The environment's layout; what a point mass lacks (velocities, orientation) is zero."""
    arm = np.concatenate([hand, np.zeros(ARM_SIZE - 3)])
    objects = np.zeros((len(colours), OBJECT_SIZE))
    objects[:, 0:3] = positions
    objects[:, 3:6] = positions - hand
    objects[np.arange(len(colours)), 19 + colours] = 1.0
    objects[:, 19 + len(COLOURS) + SHAPES.index("cube")] = 1.0
    return np.concatenate([arm, objects.ravel()]).astype(np.float32)


def episode(
    rng: np.random.Generator, n_objects: int, radius: float, agent: SACAgent | None, deterministic: bool = False
) -> tuple[EpisodeData, bool]:
    """One episode, acting at random when ``agent`` is None."""
    colours = rng.choice(len(COLOURS), n_objects, replace=False)
    goal = int(rng.integers(n_objects))
    positions = np.c_[rng.uniform(-0.15, 0.15, (n_objects, 2)), np.full(n_objects, HEIGHT / 2)]
    tokens = VOCABULARY.encode(f"reach the {COLOURS[colours[goal]]} cube")
    hand = START.copy()
    observations, next_observations, actions, achieved = [], [], [], []
    for _ in range(LIMIT):
        obs = observe(hand, positions, colours)
        if agent is None:
            action = rng.uniform(-1.0, 1.0, 3).astype(np.float32)
        else:
            action = agent.act({"observation": obs, "instruction": tokens}, deterministic)
        hand = np.clip(hand + STEP * action, LOW, HIGH)
        touching = np.linalg.norm(positions - hand, axis=1) < radius
        observations.append(obs)
        actions.append(action)
        next_observations.append(observe(hand, positions, colours))
        achieved.append(touching)
        if touching[goal]:
            break
    reached = np.array(achieved)
    steps = len(actions)
    terminated = np.zeros(steps, dtype=bool)
    terminated[-1] = reached[-1, goal]
    sentences = np.tile(tokens, (steps, 1))
    data = EpisodeData(
        observations=np.array(observations),
        next_observations=np.array(next_observations),
        instructions=sentences,
        next_instructions=sentences.copy(),
        actions=np.array(actions, dtype=np.float32),
        rewards=np.where(reached[:, goal], 0.0, -1.0).astype(np.float32),
        terminated=terminated,
        achieved=reached,
        goal_index=goal,
        objects=tuple(ObjectProps(COLOURS[c], "cube") for c in colours),
        task="reach",
    )
    return data, bool(terminated[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=40000)
    parser.add_argument("--objects", type=int, default=2, choices=(1, 2, 3))
    parser.add_argument("--radius", type=float, default=0.03, help="touching distance (m)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--agent", nargs="*", default=[], metavar="NAME=VALUE", help="agent settings")
    parser.add_argument("--out", type=Path, help="CSV of the evaluations")
    args = parser.parse_args()
    torch.set_num_threads(1)

    try:
        settings = AgentConfig.model_validate({**AGENT, **agent_overrides(args.agent)}).settings()
    except ValidationError as error:
        raise SystemExit(f"--agent: {error}") from None
    layout = ObjectLayout(ARM_SIZE, OBJECT_SIZE, args.objects)
    agent = SACAgent(layout.size, 3, len(VOCABULARY), settings, seed=args.seed, layout=layout)
    buffer = ReplayBuffer(
        BufferSettings().size,
        layout.size,
        3,
        max_objects=args.objects,
        vocabulary=VOCABULARY,
        negations=False,
        seed=args.seed,
    )
    collect_rng, learn_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(args.seed).spawn(2))
    rows = []
    steps, successes, started = 0, [], time.perf_counter()
    while steps < args.steps:
        data, success = episode(collect_rng, args.objects, args.radius, agent if steps >= RANDOM_STEPS else None)
        buffer.add_episode(data)
        agent.update_normalizer(data.observations)
        successes.append(success)
        if steps >= RANDOM_STEPS:
            agent.learn(buffer, learn_rng, len(data))
        before, steps = steps, steps + len(data)
        if steps // EVAL_EVERY > before // EVAL_EVERY:
            evaluation = np.mean(
                [
                    episode(np.random.default_rng(10_000 + i), args.objects, args.radius, agent, True)[1]
                    for i in range(EVAL_EPISODES)
                ]
            )
            row = {
                "env_steps": steps,
                "wall_time": round(time.perf_counter() - started, 1),
                "train_success": round(float(np.mean(successes[-50:])), 3),
                "eval_success": round(float(evaluation), 3),
            }
            rows.append(row)
            print(", ".join(f"{k} {v}" for k, v in row.items()), flush=True)
            if args.out is not None:
                with args.out.open("w", newline="") as f:
                    writer = csv.DictWriter(f, fieldnames=list(row))
                    writer.writeheader()
                    writer.writerows(rows)


if __name__ == "__main__":
    main()
