"""Batches of a curriculum's stage, recorded for the update benchmarks (``update_profile.py``,
``compiled_update.py``), which time and profile updates on the same batches. Importing this needs no PyBullet:
only recording does, so a machine without it can time batches recorded elsewhere."""

from __future__ import annotations

import argparse

from lanrocli.agent.sac import SACAgent
from lanrocli.agent.buffer.transitions import Batch


def batch_arguments(parser: argparse.ArgumentParser, stage: int, updates: int) -> None:
    """The options that say which batches :func:`record_batches` records, and how many."""
    parser.add_argument("--curriculum", default="reach", help="whose agent settings (a packaged name or a file)")
    parser.add_argument("--stage", type=int, default=stage, help="whose environment collects the batches (from 1)")
    parser.add_argument("--collect", type=int, default=1500)
    parser.add_argument("--updates", type=int, default=updates)


def record_batches(args: argparse.Namespace, parser: argparse.ArgumentParser) -> tuple[SACAgent, list[Batch]]:
    """The curriculum's agent after ``--collect`` steps of its stage ``--stage``, untrained, and ``--updates``
    batches sampled from what it collected, as that stage samples them."""
    from lanrocli.config.curriculum import find_curriculum, load_curriculum
    from lanrocli.train.trainer import Trainer, TrainSettings

    curriculum = load_curriculum(find_curriculum(args.curriculum))
    if not 1 <= args.stage <= len(curriculum.stages):
        parser.error(f"--stage must be from 1 to {len(curriculum.stages)}, the stages of {args.curriculum}")
    index = args.stage - 1
    settings = TrainSettings(
        task=curriculum.task, env=curriculum.stages[index].env.settings(), envs=2,
        learning_starts=args.collect + 1, buffer=curriculum.buffer_settings(index), object_slots=curriculum.max_objects,
        max_corrections=curriculum.max_corrections, stage=index,
    )
    trainer = Trainer(settings, curriculum.agent.settings())
    trainer.run(args.collect)
    trainer.close()
    agent, rng = trainer.agent, trainer.rng
    return agent, [trainer.buffer.sample(agent.settings.batch_size, rng, settings.buffer) for _ in range(args.updates)]


def twin(agent: SACAgent, **settings: object) -> SACAgent:
    """The same agent (weights, optimiser, noise stream) with these settings changed (``compile``, ``replay``)."""
    state = agent.state_dict()
    state["settings"] = {**state["settings"], **settings}
    return SACAgent.from_state_dict(state, agent.device)

