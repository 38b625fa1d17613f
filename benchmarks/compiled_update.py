"""How much ``torch.compile`` makes the shipped agent's update faster on CPU, compiled two ways, timed against
``SACAgent.update`` eager on the same recorded batches, alternating rounds:

- ``compile: true`` (``SACSettings.compile``, what ``lanro`` trains with when asked): the losses after the
  sentences' reading (:func:`lanrocli.agent.losses.sac_losses`), whose shapes never change, compiled; the
  sentences read eagerly, each distinct one once, packed by length.
- whole (an experiment): the sentences' reading compiled too. Its shapes change from batch to batch (the
  number of distinct sentences, the longest one), so here they are fixed: all of a batch's sentences are
  read, none deduplicated, over the vocabulary's full sentence length with a mask.
- eager and ``compile: true`` with the sentences read in advance (a bound, not an update): each batch's
  summaries are read once before the clock starts, so these time everything an update does but the GRUs'
  reading, forward and backward: what an update would cost if reading were free.

    python benchmarks/compiled_update.py --stage 3 --updates 100 --rounds 3

On a GPU an update of this size is bound by kernel launches (docs/performance.md), which CUDA graphs
remove, and fixed shapes are what a graph needs: ``--device cuda --mode reduce-overhead`` times the whole
update that way. A machine without PyBullet can time batches recorded on one with it:

    python benchmarks/compiled_update.py --stage 3 --updates 100 --save recorded.pt
    python benchmarks/compiled_update.py --load recorded.pt --device cuda --mode reduce-overhead
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import torch
from recorded_batches import batch_arguments, record_batches, twin

from lanrocli.agent.encoder import encode, stacked_gates
from lanrocli.agent.losses import UpdateTensors, sac_losses, update_tensors
from lanrocli.agent.sac import SACAgent
from lanrocli.agent.settings import UPDATE_METRICS
from lanrocli.agent.buffer.transitions import Batch
from lanrocli.language import PAD_ID


def read_all(tables: torch.Tensor, w_hh: torch.Tensor, b_hh: torch.Tensor, tokens: torch.Tensor) -> torch.Tensor:
    """Each encoder's GRU state after the last word of every sentence, [encoders, S, hidden]: ``tables`` [E,
    V, 3H] are the words' input gates, the padding leaves a state as it was."""
    sentences, length = tokens.shape
    hidden = w_hh.shape[2]
    gates_in = tables.index_select(1, tokens.t().reshape(-1)).reshape(tables.shape[0], length, sentences, -1).unbind(1)
    words = (tokens != PAD_ID).t().unsqueeze(-1).to(tables.dtype).unbind(0)
    h = tables.new_zeros(tables.shape[0], sentences, hidden)
    for x, word in zip(gates_in, words):
        gh = torch.baddbmm(b_hh.unsqueeze(1), h, w_hh.transpose(1, 2))
        r = torch.sigmoid(x[..., :hidden] + gh[..., :hidden])
        z = torch.sigmoid(x[..., hidden : 2 * hidden] + gh[..., hidden : 2 * hidden])
        n = torch.tanh(x[..., 2 * hidden :] + r * gh[..., 2 * hidden :])
        h = word * ((1 - z) * n + z * h) + (1 - word) * h
    return h


def whole_losses(
    agent: SACAgent, tensors: UpdateTensors, tokens: torch.Tensor, labelled: bool
) -> tuple[torch.Tensor, torch.Tensor]:
    """``SACAgent.update``'s summed loss and its metrics, the sentences read in fixed shapes: every sentence
    over the vocabulary's full length (for an agent with its own actor encoder, as the shipped curricula's)."""
    return sac_losses(agent, read_all(*stacked_gates(agent._update_encoders()), tokens), tensors, labelled)


def whole_update(agent: SACAgent, compiled: Callable[..., tuple[torch.Tensor, torch.Tensor]], batch: Batch) -> dict[str, float]:
    """One update of ``agent`` with the losses compiled whole: as ``SACAgent.update``, but for the sentences'
    reading."""
    sampled, tokens = agent._sampled_tensors(batch)
    loss, metrics = compiled(agent, update_tensors(agent, sampled), tokens, batch.labelled)
    del loss_placeholderagent, tensors, tokens, batch.labelled)
    agent._backward(loss)
    agent._step()
    return dict(zip(UPDATE_METRICS, metrics.tolist()))


def read_in_advance(agent: SACAgent, batches: list[Batch]) -> Callable[[Batch], None]:
    """An update of ``agent`` given each batch's sentence summaries, read once now (by a copy of it, so that
    its noise stream is untouched): everything ``SACAgent.update`` does but reading them. The summaries are
    leaves that take their gradient, so the backward pass stops where the encoders' would begin."""
    reader = SACAgent.from_state_dict(agent.state_dict(), agent.device)
    with torch.no_grad():
        summaries = [encode(reader._update_encoders(), reader._sampled_tensors(batch)[1]) for batch in batches]
    by_batch = {id(batch): summary for batch, summary in zip(batches, summaries)}

    def update(batch: Batch) -> None:
        tensors = update_tensors(agent, agent._sampled_tensors(batch)[0])
        read = by_batch[id(batch)].clone().requires_grad_()
        loss, _ = agent._losses(agent, read, tensors, batch.labelled)
        agent._backward(loss)
        agent._step()

    return update


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    batch_arguments(parser, stage=3, updates=100)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--mode", default=None, help="torch.compile's mode (reduce-overhead: CUDA graphs)")
    parser.add_argument("--save", type=Path, help="record the agent and batches to this file, and stop")
    parser.add_argument("--load", type=Path, help="time on the agent and batches recorded in this file")
    args = parser.parse_args()
    torch.set_num_threads(1)

    if args.load is not None:
        recorded = torch.load(args.load, weights_only=True)
        eager = SACAgent.from_state_dict(recorded["agent"], args.device)
        batches = [Batch(**{name: value.numpy() for name, value in batch.items()}) for batch in recorded["batches"]]
    else:
        eager, batches = record_batches(args, parser)
        if args.save is not None:
            arrays = [{name: torch.as_tensor(value) for name, value in dataclasses.asdict(b).items()} for b in batches]
            torch.save({"agent": eager.state_dict(), "batches": arrays}, args.save)
            return
        if args.device != "cpu":
            eager = SACAgent.from_state_dict(eager.state_dict(), args.device)
    if eager.actor.encoder is None or eager.actor.reader is None:
        parser.error("the experiment is written for an object-wise agent with its own actor encoder (reach.yaml's)")
    eager = twin(eager, replay=False)  # the update from Python, which the compiled ones are timed against
    losses_compiled = twin(eager, compile=True)
    whole = SACAgent.from_state_dict(eager.state_dict(), args.device)
    compiled = torch.compile(whole_losses, dynamic=False, mode=args.mode)
    theirs = list(SACAgent.from_state_dict(eager.state_dict(), args.device).update(batches[0]).values())
    for name, update in (("compile: true", losses_compiled.update), ("whole", partial(whole_update, whole, compiled))):
        start = time.perf_counter()
        ours = list(update(batches[0]).values())
        gap = max(abs(a - b) / max(abs(b), 1e-6) for a, b in zip(ours, theirs))  # the same agent, noise and batch
        print(f"{name}: compiling {time.perf_counter() - start:.1f} s; the first update's losses and metrics "
              f"against SACAgent.update's: largest relative difference {gap:.1e}")
    updates = {
        "eager": eager.update, "compile: true": losses_compiled.update, "whole": partial(whole_update, whole, compiled),
        "eager, read in advance": read_in_advance(SACAgent.from_state_dict(eager.state_dict(), args.device), batches),
        "compile: true, read in advance": read_in_advance(twin(eager, compile=True), batches),
    }
    for update in updates.values():  # warm-up
        for batch in batches[:5]:
            update(batch)
    for round_ in range(1, args.rounds + 1):
        times = {}
        for name, update in updates.items():
            start = time.perf_counter()
            for batch in batches:
                update(batch)
            times[name] = (time.perf_counter() - start) / len(batches) * 1000
        print(f"round {round_}: ms per update " + ", ".join(f"{name} {ms:.2f}" for name, ms in times.items())
              + "; " + ", ".join(f"eager / {name} {times['eager'] / ms:.2f}" for name, ms in times.items() if name != "eager"))


if __name__ == "__main__":
    main()
