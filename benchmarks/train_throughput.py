"""Training throughput: environment steps/s and gradient updates/s of a real training run, split into time
spent waiting for the simulation, sampling (and relabelling) batches, and updating the networks.

Settings: reach with 2 objects, 2 environments (subprocesses), one update per environment step, batch 256
(``--batch-size``, for both agents), on the CPU (``--device``, for both agents), updates starting after
``--learning-starts`` steps.
Our agent is ``SACSettings``' default network (``--architecture``), or with ``--curriculum`` the agent and replay
buffer a curriculum trains (its batch size too, unless ``--batch-size`` is given): ``--curriculum reach`` is the
agent every shipped curriculum inherits. If stable-baselines3
is installed, its SAC (``MultiInputPolicy``, same batch, same update ratio, same environment, same steps) runs
in the same session and the ratio is printed. With ``--rounds N`` the two alternate N times and the medians
are reported, which evens out a shared machine's drift better than one long run each.

    python benchmarks/train_throughput.py --steps 2000 --rounds 3
    python benchmarks/train_throughput.py --steps 2000 --rounds 3 --curriculum reach [--compile]

With ``--compile`` our agent's update is compiled (``SACSettings.compile``); its first update, which compiles, is
timed apart and left out of the rates, which is what a long run sees.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import time
from typing import Any

import torch

from lanrocli.agent.settings import BufferSettings, SACSettings
from lanrocli.config.curriculum import find_curriculum, load_curriculum
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.settings import EnvSettings
from lanrocli.train.trainer import Trainer, TrainSettings


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


def run_ours(
    steps: int,
    envs: int,
    learning_starts: int,
    seed: int,
    agent: SACSettings,
    buffer: BufferSettings,
    device: str,
) -> dict[str, float]:
    settings = TrainSettings(
        task="reach", env=EnvSettings(objects=2), seed=seed, envs=envs, learning_starts=learning_starts, buffer=buffer
    )
    trainer = Trainer(settings, agent, device=device)
    simulation, sampling, updating = Stopwatch(), Stopwatch(), Stopwatch()
    trainer.run(envs)  # start the environments before the clock
    collector = trainer._collector
    assert collector is not None
    collector.step_wait = simulation.wrap(collector.step_wait)  # type: ignore[method-assign]
    trainer.buffer.sample = sampling.wrap(trainer.buffer.sample)  # type: ignore[method-assign]
    original = trainer.agent.update
    trainer.agent.update = updating.wrap(original)  # type: ignore[method-assign]
    compiling = Stopwatch()
    if agent.compile:  # the first update compiles: timed apart, and left out of the rates
        timed, first = trainer.agent.update, compiling.wrap(original)

        def update(batch):  # type: ignore[no-untyped-def]
            trainer.agent.update = timed  # type: ignore[method-assign]
            return first(batch)

        trainer.agent.update = update  # type: ignore[method-assign]
    updates_before = trainer.progress.updates
    start = time.perf_counter()
    trainer.run(steps)
    total = time.perf_counter() - start - compiling.seconds
    trainer.close()
    done = steps - envs
    return {
        "env_steps_per_s": done / total,
        "updates_per_s": (trainer.progress.updates - updates_before) / total,
        "seconds": total,
        "simulation_wait_s": simulation.seconds,
        "sampling_s": sampling.seconds,
        "update_s": updating.seconds,
        "compile_s": compiling.seconds,
    }


def run_sb3(
    steps: int, envs: int, learning_starts: int, seed: int, batch_size: int, device: str
) -> dict[str, float] | None:
    try:
        from stable_baselines3 import SAC
        from stable_baselines3.common.vec_env import SubprocVecEnv
    except ImportError:
        return None
    vec = SubprocVecEnv([lambda: LanroEnv("reach", objects=2) for _ in range(envs)])
    model = SAC(
        "MultiInputPolicy",
        vec,
        batch_size=batch_size,
        train_freq=1,
        gradient_steps=-1,  # one update per environment step collected, as ours
        learning_starts=learning_starts,
        seed=seed,
        device=device,
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
    parser.add_argument("--threads", type=int, default=1, help="torch's threads within an operation (both agents)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--batch-size", type=int, help="of both agents (default: 256, or the curriculum's)")
    parser.add_argument("--architecture", choices=["flat", "objects"], help="of our agent (default: flat)")
    parser.add_argument("--curriculum", help="our agent and buffer are this curriculum's (a packaged name or a file)")
    parser.add_argument("--rounds", type=int, default=1, help="alternate ours and stable-baselines3 this many times")
    parser.add_argument("--device", default="cpu", help="where both agents learn: cpu, cuda or cuda:N")
    parser.add_argument("--compile", action="store_true", help="our agent's update compiled (SACSettings.compile)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.rounds < 1:
        parser.error("--rounds must be at least 1")
    if args.curriculum is not None and args.architecture is not None:
        parser.error("--architecture and --curriculum both choose our agent: give one")
    torch.set_num_threads(args.threads)
    if args.curriculum is not None:
        curriculum = load_curriculum(find_curriculum(args.curriculum))
        agent, buffer = curriculum.agent.settings(), curriculum.buffer.settings()
    else:
        agent, buffer = SACSettings(architecture=args.architecture or "flat"), BufferSettings()
    if args.batch_size is not None:
        agent = dataclasses.replace(agent, batch_size=args.batch_size)
    if args.compile:
        agent = dataclasses.replace(agent, compile=True)

    rounds = []
    for _ in range(args.rounds):
        result = run_ours(args.steps, args.envs, args.learning_starts, args.seed, agent, buffer, args.device)
        sb3 = run_sb3(args.steps, args.envs, args.learning_starts, args.seed, agent.batch_size, args.device)
        if sb3 is not None:
            result.update(sb3, ratio=result["env_steps_per_s"] / sb3["sb3_env_steps_per_s"])
        rounds.append(result)
    median: dict[str, Any] = {key: statistics.median(r[key] for r in rounds) for key in rounds[0]}
    if "ratio" in median:
        median["ratios"] = [r["ratio"] for r in rounds]
    if args.json:
        print(json.dumps(median))
        return
    print(f"lanro: {median['env_steps_per_s']:.0f} env steps/s, {median['updates_per_s']:.0f} updates/s")
    print(
        f"  of {median['seconds']:.1f} s: waiting for simulation {median['simulation_wait_s']:.1f} s, "
        f"sampling {median['sampling_s']:.1f} s, updates {median['update_s']:.1f} s"
        + (f" (compiling before: {median['compile_s']:.1f} s)" if args.compile else "")
    )
    if "ratio" in median:
        print(
            f"stable-baselines3 SAC: {median['sb3_env_steps_per_s']:.0f} env steps/s, "
            f"{median['sb3_updates_per_s']:.0f} updates/s"
        )
        each = ", ".join(f"{r:.2f}x" for r in median["ratios"])
        print(f"ratio: {median['ratio']:.2f}x" + (f" (median of rounds {each})" if args.rounds > 1 else ""))


if __name__ == "__main__":
    main()
