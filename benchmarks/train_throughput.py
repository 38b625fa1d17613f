"""Training throughput: environment steps/s and gradient updates/s of a real training run, split into time
spent waiting for the simulation, sampling (and relabelling) batches, and updating the networks.

Settings: reach with 2 objects, 2 environments (subprocesses), one update per environment step, batch 256,
updates starting after ``--learning-starts`` steps. If stable-baselines3 is installed, its SAC
(``MultiInputPolicy``, same batch, same update ratio, same environment, same steps) runs in the same session
and the ratio is printed.

    python benchmarks/train_throughput.py --steps 4000
"""

from __future__ import annotations

import argparse
import json
import time

import torch

from lanrocli.agent import SACSettings
from lanrocli.envs import LanroEnv
from lanrocli.train import Trainer, TrainSettings


class Stopwatch:
    """Accumulates the time spent inside a wrapped callable."""

    def __init__(self) -> None:
        self.seconds = 0.0

    def wrap(self, fn):  # type: ignore[no-untyped-def]
        def timed(*args, **kwargs):  # type: ignore[no-untyped-def]
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - start

        return timed


def run_ours(steps: int, envs: int, learning_starts: int, seed: int, architecture: str) -> dict[str, float]:
    settings = TrainSettings(task="reach", env={"objects": 2}, seed=seed, envs=envs, learning_starts=learning_starts)
    trainer = Trainer(settings, SACSettings(batch_size=256, updates_per_step=1, architecture=architecture))
    simulation, sampling, updating = Stopwatch(), Stopwatch(), Stopwatch()
    trainer.run(envs)  # start the environments before the clock
    collector = trainer._collector
    assert collector is not None
    collector.step_wait = simulation.wrap(collector.step_wait)  # type: ignore[method-assign]
    trainer.buffer.sample = sampling.wrap(trainer.buffer.sample)  # type: ignore[method-assign]
    trainer.agent.update = updating.wrap(trainer.agent.update)  # type: ignore[method-assign]
    updates_before = trainer.progress.updates
    start = time.perf_counter()
    trainer.run(steps)
    total = time.perf_counter() - start
    trainer.close()
    done = steps - envs
    return {
        "env_steps_per_s": done / total,
        "updates_per_s": (trainer.progress.updates - updates_before) / total,
        "seconds": total,
        "simulation_wait_s": simulation.seconds,
        "sampling_s": sampling.seconds,
        "update_s": updating.seconds,
    }


def run_sb3(steps: int, envs: int, learning_starts: int, seed: int) -> dict[str, float] | None:
    try:
        from stable_baselines3 import SAC
        from stable_baselines3.common.vec_env import SubprocVecEnv
    except ImportError:
        return None
    vec = SubprocVecEnv([lambda: LanroEnv("reach", objects=2) for _ in range(envs)])
    model = SAC(
        "MultiInputPolicy",
        vec,
        batch_size=256,
        train_freq=1,
        gradient_steps=-1,  # one update per environment step collected, as ours
        learning_starts=learning_starts,
        seed=seed,
        device="cpu",
        verbose=0,
    )
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    total = time.perf_counter() - start
    vec.close()
    return {"sb3_env_steps_per_s": steps / total, "sb3_updates_per_s": model._n_updates / total}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--envs", type=int, default=2)
    parser.add_argument("--learning-starts", type=int, default=500)
    parser.add_argument("--threads", type=int, default=1, help="torch threads (both agents)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--architecture", choices=["flat", "objects"], default="flat", help="of our agent")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    result: dict[str, float] = run_ours(args.steps, args.envs, args.learning_starts, args.seed, args.architecture)
    sb3 = run_sb3(args.steps, args.envs, args.learning_starts, args.seed)
    if sb3 is not None:
        result.update(sb3)
        result["ratio"] = result["env_steps_per_s"] / sb3["sb3_env_steps_per_s"]
    if args.json:
        print(json.dumps(result))
        return
    print(f"lanro: {result['env_steps_per_s']:.0f} env steps/s, {result['updates_per_s']:.0f} updates/s")
    print(
        f"  of {result['seconds']:.1f} s: waiting for simulation {result['simulation_wait_s']:.1f} s, "
        f"sampling {result['sampling_s']:.1f} s, updates {result['update_s']:.1f} s"
    )
    if sb3 is not None:
        print(f"stable-baselines3 SAC: {sb3['sb3_env_steps_per_s']:.0f} env steps/s, {sb3['sb3_updates_per_s']:.0f} updates/s")
        print(f"ratio: {result['ratio']:.2f}x")


if __name__ == "__main__":
    main()
