"""Whether ``torch.compile`` makes the shipped agent's update faster on CPU: an experiment, not the update
``lanro`` trains with.

``SACAgent.update`` changes shape from batch to batch (the number of distinct sentences, the longest one), so
compiling it recompiles without end. Here every shape is fixed: all of a batch's sentences are read (none
deduplicated) over the vocabulary's full sentence length with a mask, the policy's noise is drawn outside,
the critic judges the policy's action through detached weights instead of a frozen module, and the
grounding loss is a masked sum. The losses are compiled whole (forward and backward, inductor); the
optimiser step and the target's update stay eager, as in ``SACAgent.update``. The script times it against
``SACAgent.update`` on the same recorded batches, alternating rounds:

    python benchmarks/compiled_update.py --stage 3 --updates 100 --rounds 3

On a GPU an update of this size is bound by kernel launches (docs/performance.md), which CUDA graphs
remove, and fixed shapes are what a graph needs: ``--device cuda --mode reduce-overhead`` times that. A
machine without PyBullet can time batches recorded on one with it:

    python benchmarks/compiled_update.py --stage 3 --updates 100 --save recorded.pt
    python benchmarks/compiled_update.py --load recorded.pt --device cuda --mode reduce-overhead
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from recorded_batches import batch_arguments, record_batches

from lanrocli.agent.sac import SACAgent
from lanrocli.agent.transitions import Batch
from lanrocli.language import PAD_ID
from lanrocli.reward import FAILURE_REWARD, SUCCESS_REWARD


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


def losses(agent: SACAgent, inputs: dict[str, torch.Tensor], encoders: list[tuple[torch.Tensor, ...]]) -> tuple[torch.Tensor, torch.Tensor]:
    """``SACAgent.update``'s summed loss and its metrics, in fixed shapes (for an agent with its own actor
    encoder and object-wise readers, as the shipped curricula's)."""
    s, actor, critic = agent.settings, agent.actor, agent.critic
    alpha = agent.log_alpha.detach().exp()
    tables = torch.stack([torch.addmm(b_ih, words, w_ih.t()) for words, w_ih, b_ih, _, _ in encoders])
    summaries = read_all(tables, torch.stack([e[3] for e in encoders]), torch.stack([e[4] for e in encoders]), inputs["tokens"])
    batch = inputs["reward"].shape[0]
    critic_language, next_target_language = summaries[0, :batch], summaries[2, batch:].detach()
    actor_language, next_actor_language = summaries[1].chunk(2)
    with torch.no_grad():
        next_action, next_log_prob = actor.sample(
            inputs["next_obs"], next_actor_language, None, inputs["next_present"], noise=inputs["next_noise"]
        )
        next_q = agent.target_critic(inputs["next_obs"], next_target_language, next_action, inputs["next_present"])
        target_q = inputs["reward"] + inputs["discount"] * inputs["not_done"] * (next_q.min(dim=0).values - alpha * next_log_prob)
        target_q = target_q + inputs["discount"] * inputs["failed"] * (FAILURE_REWARD / (1.0 - s.gamma))
        target_q = target_q.clamp(FAILURE_REWARD / (1.0 - s.gamma), SUCCESS_REWARD)
    obs, present = inputs["obs"], inputs["present"]
    critic_scores = critic.reader.scores(obs, critic_language, present)
    actor_scores = actor.reader.scores(obs, actor_language, present)
    observed = critic.observe(obs, critic_language, present, critic_scores)
    q = critic.value(observed, inputs["action"])
    critic_loss = (q - target_q).pow(2).mean(dim=1).sum()
    pi_action, log_prob = actor.sample(obs, actor_language, None, present, actor_scores, noise=inputs["noise"])
    first = critic.body[0]
    h = torch.baddbmm(observed.detach(), pi_action.expand(critic.n_critics, -1, -1), first.weight[:, -critic.action_dim :].detach())
    for layer in [*critic.body[1:], critic.q]:
        h = torch.relu(h) if isinstance(layer, torch.nn.ReLU) else torch.baddbmm(layer.bias.detach(), h, layer.weight.detach())
    actor_loss = (alpha * log_prob - h.squeeze(2).min(dim=0).values).mean()
    label = inputs["label"]
    labelled = (label >= 0).to(obs.dtype)
    grounding_loss = obs.new_zeros(())
    for scores in (critic_scores, actor_scores):
        chosen = scores.log_softmax(-1).gather(2, label.clamp(min=0).expand(scores.shape[0], -1).unsqueeze(-1)).squeeze(-1)
        grounding_loss = grounding_loss - (chosen * labelled).sum() / (labelled.sum().clamp(min=1) * scores.shape[0])
    alpha_loss = -(agent.log_alpha * (log_prob.detach() + agent.target_entropy)).mean()
    total = critic_loss + actor_loss + alpha_loss + s.grounding * grounding_loss
    metrics = [critic_loss, actor_loss, alpha_loss, grounding_loss, alpha, q.mean(), target_q.mean(), -log_prob.mean()]
    return total, torch.stack(metrics)


def compiled_update(agent: SACAgent, compiled: Callable[..., tuple[torch.Tensor, torch.Tensor]], batch: Batch) -> list[float]:
    """One update of ``agent`` with the compiled losses: as ``SACAgent.update``, but for the losses' form."""
    def tensor(array: np.ndarray, dtype: torch.dtype) -> torch.Tensor:
        return torch.as_tensor(np.asarray(array), device=agent.device).to(dtype)

    raw, next_raw = tensor(batch.obs, torch.float32), tensor(batch.next_obs, torch.float32)
    rows, actions = raw.shape[0], agent.action_dim
    inputs = {
        "obs": agent.normalizer(raw), "present": agent.layout.present(raw),
        "next_obs": agent.normalizer(next_raw), "next_present": agent.layout.present(next_raw),
        "tokens": torch.cat([tensor(batch.instruction, torch.int64), tensor(batch.next_instruction, torch.int64)]),
        "action": tensor(batch.action, torch.float32), "reward": tensor(batch.reward, torch.float32),
        "not_done": 1.0 - tensor(batch.done, torch.float32), "discount": agent.settings.gamma ** tensor(batch.steps, torch.float32),
        "failed": tensor(batch.failed, torch.float32), "label": tensor(batch.label, torch.int64),
        "next_noise": torch.randn(rows, actions, generator=agent.generator, device=agent.device),
        "noise": torch.randn(rows, actions, generator=agent.generator, device=agent.device),
    }
    encoders = [
        (e.embedding.weight, e.gru.weight_ih_l0, e.gru.bias_ih_l0, e.gru.weight_hh_l0, e.gru.bias_hh_l0)
        for e in (agent.critic.encoder, agent.actor.encoder, agent.target_critic.encoder)
    ]
    total, metrics = compiled(agent, inputs, encoders)
    agent.optimizer.zero_grad(set_to_none=True)
    total.backward()
    agent.optimizer.step()
    with torch.no_grad():
        torch._foreach_lerp_(list(agent.target_critic.parameters()), list(agent.critic.parameters()), 1.0 - agent.settings.polyak)
    return metrics.tolist()


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
    agent = SACAgent.from_state_dict(eager.state_dict(), args.device)
    compiled = torch.compile(losses, dynamic=False, mode=args.mode)
    start = time.perf_counter()
    ours = compiled_update(agent, compiled, batches[0])
    print(f"compiling: {time.perf_counter() - start:.1f} s")
    theirs = list(eager.update(batches[0]).values())  # the same agent, noise and batch: the same losses
    gap = max(abs(a - b) / max(abs(b), 1e-6) for a, b in zip(ours, theirs))
    print(f"first update's losses and metrics against SACAgent.update's: largest relative difference {gap:.1e}")
    for batch in batches[:5]:  # warm-up
        compiled_update(agent, compiled, batch)
        eager.update(batch)
    for round_ in range(1, args.rounds + 1):
        start = time.perf_counter()
        for batch in batches:
            eager.update(batch)
        eager_ms = (time.perf_counter() - start) / len(batches) * 1000
        start = time.perf_counter()
        for batch in batches:
            compiled_update(agent, compiled, batch)
        compiled_ms = (time.perf_counter() - start) / len(batches) * 1000
        print(f"round {round_}: eager {eager_ms:.2f} ms, compiled {compiled_ms:.2f} ms per update, eager / compiled {eager_ms / compiled_ms:.2f}")


if __name__ == "__main__":
    main()
