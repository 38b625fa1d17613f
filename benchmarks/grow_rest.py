"""A screen's starting point: a copy of a run's first two stages whose agent also sees the objects its
attention leaves (``agent.see_rest``), grown from the run's own agent so that it acts and values exactly as
before: the first layers' weights on the new inputs, and Adam's moments for them, start at zero.

``see_rest`` changes the networks' shapes, so no curriculum switches it on between stages; a variant that
has it from the first step learns its first stage far slower (docs/corrections.md). This grows the agent
that ended RUN's second stage instead, and writes OUT as a run that ended its second stage with it, so that
``lanro train VARIANT --from OUT`` trains the later stages with the rest in view
(``benchmarks/screens/reach-rest-late.yaml``):

    python benchmarks/grow_rest.py runs/reach-s0 runs/reach-grown-s0
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
from pathlib import Path

import numpy as np
import torch
import yaml

from lanrocli.agent.sac import SACAgent
from lanrocli.train.checkpoint import load_checkpoint, save_checkpoint
from lanrocli.config.curriculum import load_curriculum
from lanrocli.train.runfolder import CONFIG, LAST, METRICS, read_pointer, stage_folder

GROWN = ("obs_layer.weight", "actor", 1), ("obs_layer.weight", "critic", 1), ("obs_layer.weight", "target_critic", 1)
"""The first layers that read the reader's output, by network, and the axis of their input features."""


def zero_padded(tensor: torch.Tensor, axis: int, size: int) -> torch.Tensor:
    """``tensor`` with ``size`` zeros appended along ``axis``: the rest's features come last in the reader's
    output."""
    shape = list(tensor.shape)
    shape[axis] = size
    return torch.cat([tensor, tensor.new_zeros(shape)], dim=axis)


def grown(state: dict, agent: SACAgent) -> dict:
    """An agent state with ``see_rest`` on, acting and valuing as ``state`` does (``agent``: built from it)."""
    if state["settings"]["see_rest"] or state["layout"] is None:
        raise SystemExit("the run's agent already sees the rest, or reads no objects (architecture flat)")
    extra = state["layout"]["object"]
    out = dict(state, settings=dict(state["settings"], see_rest=True))
    for name, network, axis in GROWN:
        out[network] = dict(state[network], **{name: zero_padded(state[network][name], axis, extra)})
    # Adam's moments are kept per parameter, numbered as the optimiser's groups list them: critic, then actor.
    numbered = [*[f"critic.{n}" for n, _ in agent.critic.named_parameters()], *[f"actor.{n}" for n, _ in agent.actor.named_parameters()]]
    moments = {index: dict(values) for index, values in state["optimizer"]["state"].items()}
    for name, network, axis in GROWN:
        if network != "target_critic":
            entry = moments[numbered.index(f"{network}.{name}")]
            entry["exp_avg"], entry["exp_avg_sq"] = (zero_padded(entry[k], axis, extra) for k in ("exp_avg", "exp_avg_sq"))
    out["optimizer"] = dict(state["optimizer"], state=moments)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="a run that has finished its second stage")
    parser.add_argument("out", type=Path, help="a new folder")
    args = parser.parse_args()

    curriculum = load_curriculum(args.run / CONFIG)
    stages = [stage_folder(i, stage.name) for i, stage in enumerate(curriculum.stages[:2])]
    args.out.mkdir(parents=True)
    config = yaml.safe_load((args.run / CONFIG).read_text())
    config.setdefault("agent", {})["see_rest"] = True
    (args.out / CONFIG).write_text(yaml.safe_dump(config, sort_keys=False))
    shutil.copy2(args.run / METRICS, args.out / METRICS)
    for events in args.run.glob("events.*"):
        shutil.copy2(events, args.out / events.name)
    for name in stages:
        shutil.copytree(args.run / name, args.out / name, symlinks=True)
    last = read_pointer(args.out / stages[1] / LAST)
    checkpoint = load_checkpoint(last)
    before = SACAgent.from_state_dict(checkpoint.agent)
    state = grown(checkpoint.agent, before)
    after = SACAgent.from_state_dict(state)
    rng = np.random.default_rng(0)
    probe = {"observation": rng.normal(size=(64, before.obs_dim)).astype(np.float32),
             "instruction": rng.integers(1, before.vocab_size, size=(64, 16))}
    if not np.array_equal(before.act(probe, deterministic=True), after.act(probe, deterministic=True)):
        raise SystemExit("the grown agent acts otherwise than the run's: not written")
    shutil.rmtree(last)
    save_checkpoint(last, dataclasses.replace(checkpoint, agent=state))
    print(f"{args.out}: {stages[1]} ends with the grown agent ({last.name})")


if __name__ == "__main__":
    main()
