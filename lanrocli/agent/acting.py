"""What the agent computes to act, as functions of tensors: from the raw observations, the sentences as
:meth:`LanguageEncoder.distinct <lanrocli.agent.encoder.LanguageEncoder.distinct>` gives them and, for an exploring
action, the policy's noise. What depends on the words' values (which sentences are distinct, how long the longest
is) stays outside, so that each function can be recorded and replayed (:class:`~lanrocli.agent.replay.ReplayedActing`)
as the update is: acting on a few observations is about a hundred small operations, each costing more to reach
from Python than to compute."""

from __future__ import annotations

from typing import Protocol

import torch

from lanrocli.agent.encoder import LanguageEncoder
from lanrocli.agent.networks import Actor, ObjectLayout
from lanrocli.agent.normalizer import RunningNormalizer
from lanrocli.agent.settings import SACSettings
from lanrocli.core.choices import ActingAttention


class Acting(Protocol):
    """What acting reads of an agent (:class:`~lanrocli.agent.sac.SACAgent`)."""

    settings: SACSettings
    actor: Actor
    normalizer: RunningNormalizer
    layout: ObjectLayout | None

    @property
    def actor_encoder(self) -> LanguageEncoder: ...


def explore(
    agent: Acting, raw: torch.Tensor, sentences: torch.Tensor, lengths: torch.Tensor, inverse: torch.Tensor, noise: torch.Tensor
) -> list[torch.Tensor]:
    """The exploring actions [B, A] in [-1, 1] for the raw observations ``raw`` [B, N] and the policy's standard
    normal ``noise`` [B, A]."""
    x, present = observed(agent, raw)
    language = agent.actor_encoder.summarise(sentences, lengths, inverse)
    return [agent.actor.sample(x, language, None, present, noise=noise)[0]]


def exploit(
    agent: Acting, raw: torch.Tensor, sentences: torch.Tensor, lengths: torch.Tensor, inverse: torch.Tensor
) -> list[torch.Tensor]:
    """The deterministic actions [B, A] and, for an object-wise agent, the actor's attention over the object slots
    [B, slots], summing to 1 over the present objects: both from one reading of the sentences and the objects."""
    x, present = observed(agent, raw)
    language = agent.actor_encoder.summarise(sentences, lengths, inverse)
    if agent.actor.reader is None:
        return [agent.actor.mode(x, language, present)]
    scores = agent.actor.reader.scores(x, language, present)
    acting = scores if agent.settings.acting_attention == ActingAttention.SOFT else argmax_scores(scores)
    mean, _ = agent.actor(x, language, present, acting)
    return [torch.tanh(mean), scores[0].softmax(dim=-1)]


def observed(agent: Acting, raw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Normalised observations [B, N] and, for an object-wise agent, which slots hold objects."""
    return agent.normalizer(raw), None if agent.layout is None else agent.layout.present(raw)


def argmax_scores(scores: torch.Tensor) -> torch.Tensor:
    """Attention logits whose softmax is one on each row's highest score and zero elsewhere."""
    lowest = torch.full_like(scores, torch.finfo(scores.dtype).min)
    return lowest.scatter(-1, scores.argmax(dim=-1, keepdim=True), 0.0)
