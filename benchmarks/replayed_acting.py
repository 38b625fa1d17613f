"""What replaying acting's recorded operations (``ReplayedActing``, ``lanrocli/agent/replay.py``) saves against
acting from Python, on the shipped curricula's agent and observations collected in one of reach.yaml's stages:
exploring actions for the training's two environments at once, and deterministic actions with the attention
for the evaluation's four episodes side by side. Two copies of one agent act on the same observations in
alternating rounds, the replayed one recording each kind and shape of call once it recurs (as in a training),
and the run checks that their answers are identical.

    python benchmarks/replayed_acting.py --stage 3 --observations 1000 --rounds 4
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch
from recorded_batches import twin

from lanrocli.agent.sac import SACAgent
from lanrocli.config.curriculum import find_curriculum, load_curriculum
from lanrocli.train.trainer import Trainer, TrainSettings

Observation = dict[str, np.ndarray]


def collected(curriculum_name: str, stage: int, steps: int) -> tuple[SACAgent, list[Observation]]:
    """The curriculum's untrained agent and the observations its two environments showed it over ``steps``
    environment steps of the stage (counted from 1), the sentences as the stage speaks them."""
    curriculum = load_curriculum(find_curriculum(curriculum_name))
    index = stage - 1
    settings = TrainSettings(
        task=curriculum.task, env=curriculum.stages[index].env.settings(), envs=2, learning_starts=steps + 1,
        buffer=curriculum.buffer_settings(index), object_slots=curriculum.max_objects,
        max_corrections=curriculum.max_corrections, stage=index,
    )
    trainer = Trainer(settings, curriculum.agent.settings())
    seen: list[Observation] = []
    trainer.run(steps, on_step=lambda t: seen.append({k: v.copy() for k, v in t._collector.observation.items()}))  # type: ignore[union-attr]
    trainer.close()
    return trainer.agent, seen


def act_all(agent: SACAgent, pairs: list[Observation], fours: list[Observation]) -> list[np.ndarray]:
    """Every answer: an exploring action per pair of observations, actions and attention per four."""
    answers = [agent.act(obs) for obs in pairs]
    for obs in fours:
        actions, attention = agent.act_and_attend(obs)
        answers += [actions] + ([] if attention is None else [attention])
    return answers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--curriculum", default="reach", help="whose agent settings (a packaged name or a file)")
    parser.add_argument("--stage", type=int, default=3, help="whose environment shows the observations (from 1)")
    parser.add_argument("--observations", type=int, default=1000, help="pairs of observations collected")
    parser.add_argument("--rounds", type=int, default=4)
    args = parser.parse_args()
    torch.set_num_threads(1)

    agent, pairs = collected(args.curriculum, args.stage, 2 * args.observations)
    fours = [{k: np.concatenate([a[k], b[k]]) for k in a} for a, b in zip(pairs[::2], pairs[1::2])]
    agents = {"python": twin(agent, replay=False), "replayed": twin(agent, replay=True)}
    answers = {name: act_all(a, pairs, fours) for name, a in agents.items()}  # warm-up: records what recurs
    times: dict[str, list[float]] = {name: [] for name in agents}
    calls = len(pairs) + len(fours)
    for round_ in range(1, args.rounds + 1):
        for name, a in agents.items():
            start = time.perf_counter()
            answers[name] += act_all(a, pairs, fours)
            times[name].append((time.perf_counter() - start) / calls * 1000)
        print(f"round {round_}: " + ", ".join(f"{name} {ms[-1]:.3f} ms" for name, ms in times.items()) + " per call", flush=True)
    medians = {name: statistics.median(ms) for name, ms in times.items()}
    same = all(np.array_equal(p, r) for p, r in zip(answers["python"], answers["replayed"]))
    acting = agents["replayed"]._acting
    recorded = 0 if acting is None else len(acting._recordings)
    print(f"median per call ({len(pairs)} of two rows exploring, {len(fours)} of four deterministic): python "
          f"{medians['python']:.3f} ms, replayed {medians['replayed']:.3f} ms ({medians['python'] / medians['replayed']:.2f}x); "
          f"{recorded} shapes recorded; the answers are {'identical' if same else 'NOT identical'}")


if __name__ == "__main__":
    main()
