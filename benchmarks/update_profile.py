"""Where one SAC update's time goes: the agent of a curriculum (reach.yaml's by default, which every shipped
curriculum inherits) collects ``--collect`` steps in one of its stages (``--stage``, counted from 1, the first
by default; the last stage's batches hold corrections and chains), then ``--updates`` updates run under
torch's profiler. Prints the update's mean time, how many tensor operations one update runs, and
the operations that take the most time, so that a change to the update is judged by what it removes.

    python benchmarks/update_profile.py --updates 200
    python benchmarks/update_profile.py --updates 200 --stage 3 [--compile]

With ``--compile`` the update's losses are compiled (``SACSettings.compile``), the compiling done in the
warm-up.
"""

from __future__ import annotations

import argparse
import time
import torch
from torch.profiler import ProfilerActivity, profile

from recorded_batches import batch_arguments, compiled_twin, record_batches


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    batch_arguments(parser, stage=1, updates=200)
    parser.add_argument("--top", type=int, default=15)
    parser.add_argument("--compile", action="store_true", help="the update's losses compiled (SACSettings.compile)")
    args = parser.parse_args()
    torch.set_num_threads(1)

    agent, batches = record_batches(args, parser)
    if args.compile:
        agent = compiled_twin(agent)
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
    print(f"{args.curriculum}'s agent, stage {args.stage} ({s.architecture}, critics {s.critics}, batch {s.batch_size}, compile {s.compile}): "
          f"{seconds * 1000:.2f} ms per update, {ops / len(batches):.0f} aten operations per update")
    print(events.table(sort_by="self_cpu_time_total", row_limit=args.top))


if __name__ == "__main__":
    main()
