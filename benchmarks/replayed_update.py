"""What replaying an update's recorded operations from C++ (``SACSettings.replay``, ``lanrocli/agent/replay.py``)
saves against running the update from Python, on one thread and on two (``SACAgent.update_threads``), on the
shipped curricula's agent and batches recorded in one of reach.yaml's stages: three copies of one agent update
on the same batches, alternating rounds, and the run checks that their weights, the optimiser's moments and
the metrics stay identical.

    python benchmarks/replayed_update.py --stage 3 --updates 200 --rounds 4
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch
from recorded_batches import batch_arguments, record_batches, twin

from lanrocli.agent.sac import SACAgent


def identical(a: SACAgent, b: SACAgent) -> bool:
    """Every weight, the temperature and Adam's moments equal bit for bit."""
    x, y = a.state_dict(), b.state_dict()
    tensors = [(x[n][k], y[n][k]) for n in ("actor", "critic", "target_critic") for k in x[n]]
    tensors.append((x["log_alpha"], y["log_alpha"]))
    for state_x, state_y in zip(x["optimizer"]["state"].values(), y["optimizer"]["state"].values()):
        tensors += [(state_x[k], state_y[k]) for k in ("exp_avg", "exp_avg_sq")]
    return all(torch.equal(p, q) for p, q in tensors)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    batch_arguments(parser, stage=3, updates=200)
    parser.add_argument("--rounds", type=int, default=4)
    args = parser.parse_args()
    torch.set_num_threads(1)

    agent, batches = record_batches(args, parser)
    agents = {"python": twin(agent, replay=False), "one thread": twin(agent, replay=True), "two threads": twin(agent, replay=True)}
    agents["one thread"].update_threads, agents["two threads"].update_threads = 1, 2
    metrics = {name: [a.update(batch) for batch in batches[:5]] for name, a in agents.items()}  # warm-up, recording
    if agents["one thread"]._replay is None:
        parser.error("the replay could not be built here (see the warning)")
    times: dict[str, list[float]] = {name: [] for name in agents}
    for round_ in range(1, args.rounds + 1):
        for name, a in agents.items():
            start = time.perf_counter()
            metrics[name] += [a.update(batch) for batch in batches]
            times[name].append((time.perf_counter() - start) / len(batches) * 1000)
        print(f"round {round_}: " + ", ".join(f"{name} {ms[-1]:.2f} ms" for name, ms in times.items()) + " per update",
              flush=True)
    medians = {name: statistics.median(ms) for name, ms in times.items()}
    same = all(identical(agents["python"], a) and metrics["python"] == metrics[name] for name, a in agents.items())
    print("median per update: " + ", ".join(f"{name} {ms:.2f} ms ({medians['python'] / ms:.2f}x)" for name, ms in medians.items())
          + f"; two threads against one {medians['one thread'] / medians['two threads']:.2f}x; after "
          f"{len(metrics['python'])} updates each the weights, moments and metrics are {'identical' if same else 'NOT identical'}")


if __name__ == "__main__":
    main()
