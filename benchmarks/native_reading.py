"""What an update's reading of its sentences in C++ (``lanrocli/agent/native.py``, ``gru_steps.cpp``) saves
against the same reading in Python (``encoder.py``, ``gru.py``), on the shipped curricula's agent and batches
recorded in one of reach.yaml's stages, alternating rounds: the reading alone (forward and backward, as an
update reads), and whole eager updates. The two give the same numbers bit for bit, which the run checks on
the weights the updates leave.

    python benchmarks/native_reading.py --stage 3 --updates 100 --rounds 3
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from unittest import mock

import torch
from recorded_batches import batch_arguments, record_batches

from lanrocli.agent import encoder
from lanrocli.agent.encoder import encode
from lanrocli.agent.native import Reader, native_reader
from lanrocli.agent.sac import SACAgent
from lanrocli.agent.buffer.transitions import Batch


def read_all(agent: SACAgent, batches: list[Batch]) -> Callable[[], None]:
    """Each batch's sentences read by the networks an update reads them with, and the gradient sent back."""
    tokens = [agent._sampled_tensors(batch)[1] for batch in batches]
    encoders = agent._update_encoders()
    trained = sum(any(p.requires_grad for p in encoder.parameters()) for encoder in encoders)

    def run() -> None:
        for sentences in tokens:
            encode(encoders, sentences)[:trained].sum().backward()

    return run


def update_all(agent: SACAgent, batches: list[Batch]) -> Callable[[], None]:
    def run() -> None:
        for batch in batches:
            agent.update(batch)

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    batch_arguments(parser, stage=3, updates=100)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)

    agent, batches = record_batches(args, parser)
    state = agent.state_dict()
    built = native_reader()
    if built is None:
        parser.error("the C++ reading did not build on this machine (see the warning)")
    ways: dict[str, Reader | None] = {"python": None, "c++": built}
    agents = {name: SACAgent.from_state_dict(state) for name in ways}
    jobs = {
        (name, job): work
        for name in ways
        for job, work in (("reading", read_all(agents[name], batches)), ("update", update_all(agents[name], batches)))
    }
    times: dict[tuple[str, str], list[float]] = {key: [] for key in jobs}
    for _ in range(args.rounds):
        for job in ("reading", "update"):
            for name, reader in ways.items():
                with mock.patch.object(encoder, "native_reader", lambda reader=reader: reader):
                    start = time.perf_counter()
                    jobs[name, job]()
                    times[name, job].append((time.perf_counter() - start) / len(batches) * 1000)
    for job in ("reading", "update"):
        python, native = times["python", job], times["c++", job]
        print(
            f"{job}: ms per batch, Python {', '.join(f'{t:.2f}' for t in python)}; C++ {', '.join(f'{t:.2f}' for t in native)}; "
            f"Python / C++ by round {', '.join(f'{a / b:.2f}' for a, b in zip(python, native))}"
        )
    same = all(
        torch.equal(a, b)
        for network in ("actor", "critic", "target_critic")
        for a, b in zip(agents["python"].state_dict()[network].values(), agents["c++"].state_dict()[network].values())
    )
    print(f"after {args.rounds * len(batches)} updates each way the weights are {'identical' if same else 'NOT identical'}")


if __name__ == "__main__":
    main()
