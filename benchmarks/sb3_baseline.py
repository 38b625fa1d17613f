"""stable-baselines3's SAC trained on a lanro curriculum's stages, for the baselines of docs/benchmark.md.

SB3 has no curriculum, promotion or language hindsight: its ``HerReplayBuffer`` relabels ``GoalEnv``
goals (``achieved_goal``/``desired_goal`` vectors), and lanro's goal is a sentence, so SB3's SAC learns
here from the instructor's own sentences alone. What it gets that lanro's agent gets: the same stages in
the same order (each stage's training environment, holdout and object slots), a fixed step budget per
stage (``--steps``, by default the steps lanro's push runs spent in each: 20k / 20k / 30k), lanro's
sentence encoder (``LanguageExtractor``), its batch size, learning rates, discount and one update per
environment step. The model is saved after each stage, and its stage-by-stage wall time written beside it.

    python benchmarks/sb3_baseline.py --curriculum push --seed 0 --out runs/sb3/push/seed=0

Score it on the benchmark's protocols with ``python benchmarks/benchmark_page.py --sb3 runs/sb3``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from lanrocli.config.curriculum import find_curriculum, load_curriculum
from lanrocli.envs.env import LanroEnv
from lanrocli.integrations.wrappers import MultiDiscreteInstruction
from lanrocli.language import grammar_vocabulary

MODEL = "model.zip"
RECORD = "training.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--curriculum", default="push")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, nargs="+", default=[20_000, 20_000, 30_000], help="steps per stage")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument(
        "--from-stage",
        type=int,
        default=0,
        help="go on from the model saved after the stage before this one (counted from 0); its replay buffer "
        "was not saved, so it starts empty: not the run an uninterrupted one would have been",
    )
    args = parser.parse_args()

    from stable_baselines3 import SAC

    from lanrocli.integrations.sb3 import LanguageExtractor

    curriculum = load_curriculum(find_curriculum(args.curriculum))
    if len(args.steps) != len(curriculum.stages):
        raise SystemExit(f"--steps needs one budget per stage: {curriculum.name} has {len(curriculum.stages)}")
    vocabulary = grammar_vocabulary(curriculum.max_corrections)
    holdout = curriculum.holdout.settings()
    agent = curriculum.agent

    def stage_env(index: int) -> MultiDiscreteInstruction:
        settings = curriculum.stages[index].env.settings()
        env = LanroEnv(
            curriculum.task, settings, object_slots=curriculum.max_objects, vocabulary=vocabulary, holdout=holdout
        )
        return MultiDiscreteInstruction(env)

    args.out.mkdir(parents=True, exist_ok=True)
    stages = json.loads((args.out / RECORD).read_text())["stages"][: args.from_stage] if args.from_stage else []
    model = SAC(
        "MultiInputPolicy",
        stage_env(0),
        learning_rate=agent.actor_lr,
        batch_size=agent.batch_size,
        gamma=agent.gamma,
        tau=1 - agent.polyak,
        learning_starts=curriculum.learning_starts,
        train_freq=1,
        gradient_steps=1,
        policy_kwargs={"features_extractor_class": LanguageExtractor},
        seed=args.seed,
        device="cpu",
    )
    if args.from_stage:
        model = SAC.load(args.out / MODEL, env=stage_env(args.from_stage), device="cpu")
    for index, (stage, steps) in enumerate(zip(curriculum.stages, args.steps, strict=True)):
        if index < args.from_stage:
            continue
        if index:
            model.set_env(stage_env(index))
        start = time.perf_counter()
        model.learn(steps, reset_num_timesteps=index == 0 and not args.from_stage)
        stages.append({"stage": stage.name, "steps": steps, "seconds": round(time.perf_counter() - start, 1)})
        model.save(args.out / MODEL)
        record = {"curriculum": curriculum.name, "task": curriculum.task, "seed": args.seed, "stages": stages}
        if args.from_stage:
            record["resumed_at_stage"] = args.from_stage
        (args.out / RECORD).write_text(json.dumps(record, indent=1))
        print(json.dumps(stages[-1]), flush=True)


if __name__ == "__main__":
    main()
