"""Where one SAC update's time goes: the whole update, and the sentences' reading alone (the critic's and the
actor's encoders forward and backward, the target critic's forward), on a curriculum's agent and batches
sampled from a buffer its last stage's environment filled with random actions.

    python benchmarks/update_parts.py --curriculum push [--compile] [--updates 200]
    python benchmarks/update_parts.py --curriculum push --set agent.share_encoder=true agent.actor_every=2

The batches are sampled once and reused, so the timing holds the update alone: no simulation, no sampling.
With ``--compile`` the losses are compiled (``SACSettings.compile``); the first updates, which compile, are
left out of the timing.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np
import torch
import yaml

from lanrocli.agent.encoder import distinct_sentences
from lanrocli.config.curriculum import find_curriculum, load_curriculum
from lanrocli.train.trainer import Trainer, TrainSettings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--curriculum", default="push", help="a packaged curriculum's name or a file")
    parser.add_argument("--collect", type=int, default=1500, help="environment steps of random actions first")
    parser.add_argument("--updates", type=int, default=200, help="updates timed")
    parser.add_argument("--compile", action="store_true", help="the losses compiled (SACSettings.compile)")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="as lanro train --set takes them")
    args = parser.parse_args()
    torch.set_num_threads(1)
    changes = dict(setting.split("=", 1) for setting in args.set)
    curriculum = load_curriculum(find_curriculum(args.curriculum))
    curriculum = curriculum.with_settings(
        {key: yaml.safe_load(value) for key, value in changes.items()}, args.curriculum
    )
    stage = curriculum.stages[-1]
    agent_settings = dataclasses.replace(curriculum.agent.settings(), compile=args.compile)
    buffer_settings = curriculum.buffer.settings()
    settings = TrainSettings(
        task=curriculum.task,
        env=stage.env.settings(),
        envs=1,
        learning_starts=args.collect + 1,
        buffer=buffer_settings,
        object_slots=curriculum.max_objects,
        max_corrections=curriculum.max_corrections,
    )
    trainer = Trainer(settings, agent_settings)
    trainer.run(args.collect)
    agent, rng = trainer.agent, np.random.default_rng(0)
    batches = [trainer.buffer.sample(agent.settings.batch_size, rng, buffer_settings) for _ in range(args.updates)]
    trainer.close()
    for batch in batches[:10]:  # warm up (and compile)
        agent.update(batch)

    start = time.perf_counter()
    for batch in batches:
        agent.update(batch)
    update = (time.perf_counter() - start) / len(batches)

    encoders = agent._update_encoders()
    start = time.perf_counter()
    for batch in batches:
        tokens = torch.as_tensor(np.concatenate([batch.instruction, batch.next_instruction]), dtype=torch.int64)
        sentences, inverse = distinct_sentences(tokens)
        summaries = torch.stack([encoder(sentences)[inverse] for encoder in encoders[:-1]])
        with torch.no_grad():
            encoders[-1](sentences)
        summaries.sum().backward()
    reading = (time.perf_counter() - start) / len(batches)

    s = agent.settings
    print(
        f"{args.curriculum}'s agent ({s.architecture}, batch {s.batch_size}, compile {s.compile}, shared encoder "
        f"{s.share_encoder}, actor every {s.actor_every} updates): "
        f"{1e3 * update:.2f} ms an update, of which reading the sentences {1e3 * reading:.2f} ms "
        f"({100 * reading / update:.0f}%)"
    )


if __name__ == "__main__":
    main()
