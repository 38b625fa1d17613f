"""The losses of one SAC update, as one function of tensors: the algorithm's arithmetic read top to bottom.

:meth:`SACAgent.update <lanrocli.agent.sac.SACAgent.update>` turns a batch into tensors, draws the policy's
noise and reads the sentences (whose distinct rows and longest length change from batch to batch);
everything after that has the same shapes in every update. So this function can be compiled whole
(``SACSettings.compile``), forward and backward, while the encoders stay eager.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple, Protocol

import torch

from lanrocli.agent.networks import Actor, Critic, ObjectLayout, attention_loss
from lanrocli.agent.normalizer import RunningNormalizer
from lanrocli.agent.settings import SACSettings
from lanrocli.core.reward import FAILURE_REWARD, SUCCESS_REWARD


class Learner(Protocol):
    """What the losses read of an agent (:class:`~lanrocli.agent.sac.SACAgent`)."""

    settings: SACSettings
    actor: Actor
    critic: Critic
    target_critic: Critic
    log_alpha: torch.Tensor
    target_entropy: float
    normalizer: RunningNormalizer
    layout: ObjectLayout | None


class SampledTensors(NamedTuple):
    """A sampled batch as tensors, as the buffer gave it: what an update is a function of. ``observations``
    holds the batch's observations followed by its next ones, raw; ``noise`` and ``next_noise`` are the
    policy's standard normal draws, made by the agent from its own stream."""

    observations: torch.Tensor
    action: torch.Tensor
    reward: torch.Tensor
    done: torch.Tensor
    label: torch.Tensor
    noise: torch.Tensor
    next_noise: torch.Tensor


class UpdateTensors(NamedTuple):
    """A batch as the losses read it, rows of transitions: observations normalised, ``present`` the object
    slots that hold objects (None for a flat agent), ``label`` the object its sentence names (-1 where none is
    known), ``noise`` and ``next_noise`` the standard normal draws of the policy's actions in this and the next
    states."""

    obs: torch.Tensor
    present: torch.Tensor | None
    next_obs: torch.Tensor
    next_present: torch.Tensor | None
    action: torch.Tensor
    reward: torch.Tensor
    not_done: torch.Tensor
    label: torch.Tensor
    noise: torch.Tensor
    next_noise: torch.Tensor


def update_tensors(agent: Learner, sampled: SampledTensors) -> UpdateTensors:
    """The batch as the losses read it: this and the next observations normalised in one pass (row by row
    alike), flags as the numbers the losses compute with."""
    f32 = torch.float32
    raw = sampled.observations.to(f32)
    obs, next_obs = agent.normalizer(raw).chunk(2)
    present, next_present = (None, None) if agent.layout is None else agent.layout.present(raw).chunk(2)
    return UpdateTensors(
        obs=obs,
        present=present,
        next_obs=next_obs,
        next_present=next_present,
        action=sampled.action.to(f32),
        reward=sampled.reward.to(f32),
        not_done=1.0 - sampled.done.to(f32),
        label=sampled.label.to(torch.int64),
        noise=sampled.noise,
        next_noise=sampled.next_noise,
    )


def sac_losses(
    agent: Learner, summaries: torch.Tensor, batch: UpdateTensors, labelled: bool, train_actor: bool
) -> tuple[torch.Tensor, torch.Tensor]:
    """The sum of the critic's, the actor's, the temperature's and the grounding loss, and the update's
    metrics in :data:`~lanrocli.agent.settings.UPDATE_METRICS`' order; without ``train_actor``, the critic's
    and its reader's grounding loss alone, and :data:`~lanrocli.agent.settings.CRITIC_METRICS`.

    ``summaries`` [encoders, 2B, size]: the critic's, the actor's (unless it shares the critic's) and the
    target critic's readings of this (first B rows) and the next sentences. ``labelled``: whether any row
    has a ``label``. All losses are computed from the parameters as they are before the update, as the
    original SAC does; they touch disjoint parameters, so one backward pass of the sum gives every network
    its gradient.
    """
    s, actor, critic = agent.settings, agent.actor, agent.critic
    rows = batch.reward.shape[0]
    alpha = agent.log_alpha.detach().exp()
    critic_language = summaries[0, :rows]
    next_target_language = summaries[-1, rows:].detach()
    # A shared encoder learns from the critic's loss alone: the actor reads its summary detached.
    actor_language, next_actor_language = (summaries[1] if actor.encoder is not None else summaries[0].detach()).chunk(
        2
    )

    # Critic: regress on the soft Bellman target of the target critic and the current policy.
    with torch.no_grad():
        next_action, next_log_prob = actor.sample(
            batch.next_obs, next_actor_language, batch.next_noise, batch.next_present
        )
        next_q = agent.target_critic(batch.next_obs, next_target_language, next_action, batch.next_present)
        target_q = batch.reward + s.gamma * batch.not_done * (next_q.min(dim=0).values - alpha * next_log_prob)
        if s.clip_target:
            target_q = target_q.clamp(FAILURE_REWARD / (1.0 - s.gamma), SUCCESS_REWARD)
    # Object-wise readers weigh the objects once per network: the same attention serves the networks and the
    # grounding loss.
    critic_scores = actor_scores = None
    if critic.reader is not None and actor.reader is not None:
        critic_scores = critic.reader.scores(batch.obs, critic_language, batch.present)
        if train_actor:
            actor_scores = actor.reader.scores(batch.obs, actor_language, batch.present)
    observed = critic.observe(batch.obs, critic_language, batch.present, critic_scores)
    q = critic.value(observed, batch.action)
    critic_loss = (q - target_q).pow(2).mean(dim=1).sum()
    if not train_actor:
        grounding_loss = attention_loss([critic_scores], batch.label, labelled, s.grounding)
        metrics = [critic_loss, alpha, q.mean(), target_q.mean()]
        return critic_loss + s.grounding * grounding_loss, torch.stack([metric.detach() for metric in metrics])

    # Actor: maximise the critic's value plus entropy. The critic judges the policy's actions in the states it
    # has just read, both held constant, so this loss sends gradient to the actor only.
    pi_action, log_prob = actor.sample(batch.obs, actor_language, batch.noise, batch.present, actor_scores)
    q_pi = critic.value(observed.detach(), pi_action, frozen=True).min(dim=0).values
    actor_loss = (alpha * log_prob - q_pi).mean()

    grounding_loss = attention_loss([critic_scores, actor_scores], batch.label, labelled, s.grounding)

    # Temperature: raise alpha when the policy's entropy falls below the target, lower it above. (Without
    # tuning, log_alpha has no gradient and this loss is only reported.)
    alpha_loss = -(agent.log_alpha * (log_prob.detach() + agent.target_entropy)).mean()

    total = critic_loss + actor_loss + alpha_loss + s.grounding * grounding_loss
    metrics = [critic_loss, actor_loss, alpha_loss, grounding_loss, alpha, q.mean(), target_q.mean(), -log_prob.mean()]
    return total, torch.stack([metric.detach() for metric in metrics])


Losses = Callable[[Learner, torch.Tensor, UpdateTensors, bool, bool], tuple[torch.Tensor, torch.Tensor]]


def compiled_losses() -> Losses:
    """:func:`sac_losses` compiled by ``torch.compile`` for one agent, which must be the only one ever passed to it.

    Shapes are fixed (``dynamic=False``): an agent's batches all have the same size; a changed setting (a
    stage's gamma), a batch without labels or an update that leaves the actor alone compiles another entry.
    Its entries are kept apart from any other agent's (``isolate_recompiles``), and they skip the guards on the
    networks' modules, which never change after an agent is built (their parameters change in place):
    checking them on every call would cost the update for nothing.
    """
    return torch.compile(
        sac_losses,
        dynamic=False,
        isolate_recompiles=True,
        options={"guard_filter_fn": torch.compiler.skip_guard_on_all_nn_modules_unsafe},
    )
