"""Where one SAC update's time goes: the agent of a curriculum (reach.yaml's by default, which every shipped
curriculum inherits) collects ``--collect`` steps in one of its stages (``--stage``, counted from 1, the first
by default; the last stage's batches hold corrections and chains), then ``--updates`` updates run under
torch's profiler. Prints the update's mean time, how many tensor operations one update runs, and
the operations that take the most time, so that a change to the update is judged by what it removes.

    python benchmarks/update_profile.py --updates 200
    python benchmarks/update_profile.py --updates 200 --stage 3
"""

from __future__ import annotations

import argparse
import time
import torch
from torch.profiler import ProfilerActivity, profile

from lanrocli.agent.sac import SACAgent
from lanrocli.agent.transitions import Batch
from lanrocli.train.curriculum import Curriculum, find_curriculum, load_curriculum
from lanrocli.train.trainer import Trainer, TrainSettings


def record_batches(curriculum: Curriculum, stage: int, collect: int, count: int) -> tuple[SACAgent, list[Batch]]:
    """The curriculum's agent after ``collect`` steps of its stage ``stage`` (from 1), untrained, and ``count``
    batches sampled from what it collected, as that stage samples them."""
    settings = TrainSettings(
        task=curriculum.task, env=curriculum.stages[stage - 1].env.settings(), envs=2,
        learning_starts=collect + 1, buffer=curriculum.buffer_settings(stage - 1), object_slots=curriculum.max_objects,
        max_corrections=curriculum.max_corrections, stage=stage - 1,
    )
    trainer = Trainer(settings, curriculum.agent.settings())
    trainer.run(collect)
    trainer.close()
    agent, rng, sampling = trainer.agent, trainer.rng, settings.buffer.sampling()
    return agent, [trainer.buffer.sample(agent.settings.batch_size, rng, **sampling, gamma=agent.settings.gamma) for _ in range(count)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--curriculum", default="reach", help="whose agent settings (a packaged name or a file)")
    parser.add_argument("--stage", type=int, default=1, help="whose environment collects the batches (from 1)")
    parser.add_argument("--collect", type=int, default=1500)
    parser.add_argument("--updates", type=int, default=200)
    parser.add_argument("--top", type=int, default=15)
    args = parser.parse_args()
    torch.set_num_threads(1)

    curriculum = load_curriculum(find_curriculum(args.curriculum))
    if not 1 <= args.stage <= len(curriculum.stages):
        parser.error(f"--stage must be from 1 to {len(curriculum.stages)}, the stages of {args.curriculum}")
    agent, batches = record_batches(curriculum, args.stage, args.collect, args.updates)
    for batch in batches[:10]:  # warm-up
        agent.update(batch)
    start = time.perf_counter()
    for batch in batches:
        agent.update(batch)
    seconds = (time.perf_counter() - start) / len(batches)
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for batch in batches:
            agent.update(batch)
    events = prof.key_averages()
    ops = sum(e.count for e in events if e.key.startswith("aten::"))
    s = agent.settings
    print(f"{args.curriculum}'s agent, stage {args.stage} ({s.architecture}, critics {s.critics}, batch {s.batch_size}): "
          f"{seconds * 1000:.2f} ms per update, {ops / len(batches):.0f} aten operations per update")
    print(events.table(sort_by="self_cpu_time_total", row_limit=args.top))


if __name__ == "__main__":
    main()
