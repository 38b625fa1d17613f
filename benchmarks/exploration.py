"""What a random arm gives hindsight to learn from: how often it achieves the task on some object, per start.

Hindsight relabelling turns an episode into a success for a sentence that names an object the arm did the
task on, so an episode in which the random policy of the first updates achieves nothing on any object
teaches nothing but failure. For each task and way of starting an episode (the neutral pose, a random
start near the table, the open hand around an object) this rolls out uniform random actions and reports
the share of episodes that achieve the task on at least one object, the share in which both fingers touch
one object at some step, and the share of steps at which the task holds on some object.

    python benchmarks/exploration.py --tasks grasp lift --episodes 200
"""

from __future__ import annotations

import argparse

from lanrocli.envs.env import LanroEnv
from lanrocli.envs.policies import RandomPolicy
from lanrocli.tasks import task_class

STARTS = {
    "neutral": {},
    "random_start": {"random_start": 1.0},
    "object_start": {"object_start": 1.0},
}


def measure(task: str, start: str, episodes: int, objects: int, steps: int) -> dict[str, float]:
    env = LanroEnv(task, objects=objects, max_episode_steps=steps, **STARTS[start])
    policy = RandomPolicy(task)
    achieving = gripped = achieved_steps = total_steps = 0
    for seed in range(episodes):
        observation, info = env.reset(seed=seed)
        policy.reset(seed)
        any_achieved = any_gripped = False
        done = False
        while not done:
            observation, _, terminated, truncated, info = env.step(policy.act(observation, info))
            contacts = env.robot.contacts(env.objects.body_ids)
            any_gripped |= bool((contacts.left_finger & contacts.right_finger).any())
            achieved = bool(info["achieved"].any())
            any_achieved |= achieved
            achieved_steps += achieved
            total_steps += 1
            done = terminated or truncated
        achieving += any_achieved
        gripped += any_gripped
    env.close()
    return {
        "achieving": achieving / episodes,
        "both_fingers": gripped / episodes,
        "achieved_steps": achieved_steps / total_steps,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=["grasp", "lift"])
    parser.add_argument("--starts", nargs="+", default=list(STARTS), choices=list(STARTS))
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--objects", type=int, default=2)
    parser.add_argument("--steps", type=int, default=50, help="steps per episode (the plain episode limit)")
    args = parser.parse_args()
    print(f"{args.episodes} episodes of uniform random actions, {args.objects} objects, {args.steps} steps each")
    print(f"{'task':6} {'start':13} {'achieving':>9} {'both fingers':>12} {'achieved steps':>14}")
    for task in args.tasks:
        for start in args.starts:
            if start == "object_start" and not task_class(task).gripper:
                continue  # the fingers stay closed: there is no hand to open around an object
            result = measure(task, start, args.episodes, args.objects, args.steps)
            print(
                f"{task:6} {start:13} {result['achieving']:>9.1%} {result['both_fingers']:>12.1%} "
                f"{result['achieved_steps']:>14.2%}",
                flush=True,
            )


if __name__ == "__main__":
    main()
