"""Where one SAC update's time goes: the agent of a curriculum (reach.yaml's by default, which every shipped
curriculum inherits) collects ``--collect`` steps in one of its stages (``--stage``, counted from 1, the first
by default; the last stage's batches hold corrections and chains), then ``--updates`` updates run under
torch's profiler. Prints the update's mean time, how many tensor operations one update runs, and
the operations that take the most time, so that a change to the update is judged by what it removes.

    python benchmarks/update_profile.py --updates 200
    python benchmarks/update_profile.py --updates 200 --stage 3 [--python | --compile]

The update is the shipped one, its recorded operations replayed from C++ (``SACSettings.replay``); with
``--python`` it runs from Python through autograd, as it does where the replay cannot be built; with
``--compile`` the update's losses are compiled (``SACSettings.compile``), the compiling done in the warm-up.

Then it times the update's parts one by one (turning the batch into tensors; the gradients, replayed, or from
Python the sentences' reading, the losses and the backward pass; the optimiser's step), and counts the
update's floating-point operations (torch's ``FlopCounterMode``, matrix products only, the sentences read in
Python, whose arithmetic the C++ reading repeats): what the update would cost were it arithmetic alone.
"""

from __future__ import annotations

import argparse
import time
from unittest import mock

import torch
from torch.profiler import ProfilerActivity, profile
from torch.utils.flop_counter import FlopCounterMode

from recorded_batches import batch_arguments, record_batches, twin

from lanrocli.agent import encoder
from lanrocli.agent.losses import update_tensors
from lanrocli.agent.sac import SACAgent
from lanrocli.agent.buffer.transitions import Batch

def time_parts(agent: SACAgent, batches: list[Batch]) -> dict[str, float]:
    """ms per update in each part of :meth:`SACAgent.update`, whose steps this makes one by one."""
    replayed = agent._replay is not None
    parts = ("tensors", "gradients", "step") if replayed else ("tensors", "reading", "losses", "backward and step")
    seconds = dict.fromkeys(parts, 0.0)
    for batch in batches:
        times = [time.perf_counter()]
        sampled, tokens = agent._sampled_tensors(batch)
        times.append(time.perf_counter())
        if replayed:
            metrics = agent._gradients(tokens, sampled, batch.labelled)
            times.append(time.perf_counter())
        else:  # the backward pass and the step are one part
            summaries = encoder.encode(agent._update_encoders(), tokens)
            times.append(time.perf_counter())
            loss, metrics = agent._losses(agent, summaries, update_tensors(agent, sampled), batch.labelled)
            times.append(time.perf_counter())
            agent._backward(loss)
        agent._step()
        metrics.tolist()
        times.append(time.perf_counter())
        for part, begin, end in zip(parts, times, times[1:]):
            seconds[part] += end - begin
    return {part: total / len(batches) * 1000 for part, total in seconds.items()}


def count_flops(agent: SACAgent, batches: list[Batch]) -> float:
    """Floating-point operations per update (matrix products), the sentences read in Python."""
    with mock.patch.object(encoder, "native_reader", lambda: None), FlopCounterMode(display=False) as counter:
        for batch in batches:
            agent.update(batch)
    return counter.get_total_flops() / len(batches)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    batch_arguments(parser, stage=1, updates=200)
    parser.add_argument("--top", type=int, default=15)
    how = parser.add_mutually_exclusive_group()
    how.add_argument("--python", action="store_true", help="the update run from Python (SACSettings.replay false)")
    how.add_argument("--compile", action="store_true", help="the update's losses compiled (SACSettings.compile)")
    args = parser.parse_args()
    torch.set_num_threads(1)

    agent, batches = record_batches(args, parser)
    flops = count_flops(twin(agent, replay=False), batches)
    if args.compile or args.python:
        agent = twin(agent, compile=args.compile, replay=not args.python)
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
    print(f"{args.curriculum}'s agent, stage {args.stage} ({s.architecture}, critics {s.critics}, batch {s.batch_size}, compile {s.compile}, replayed {agent._replay is not None}): "
          f"{seconds * 1000:.2f} ms per update, {ops / len(batches):.0f} aten operations per update")
    print(events.table(sort_by="self_cpu_time_total", row_limit=args.top))
    parts = time_parts(agent, batches)
    print("ms per update by part: " + ", ".join(f"{part} {ms:.2f}" for part, ms in parts.items()) + f"; in all {sum(parts.values()):.2f}")
    print(f"{flops / 1e6:.1f} million floating-point operations per update (matrix products)")


if __name__ == "__main__":
    main()
