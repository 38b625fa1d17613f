"""The networks of the language-conditioned SAC: a sentence encoder, a squashed-Gaussian actor and Q critics.

Both actor and critic read an observation through a layer of ``SACSettings.obs_size`` units and join it with
a summary of the goal sentence (``language_size`` numbers; for the critic, the action too) before the hidden
layers (``hidden_size``). The sentence summary
is computed by a :class:`~lanrocli.agent.encoder.LanguageEncoder` that each network holds as ``encoder``; the
networks take the summary as an input rather than the tokens, so the agent decides whether actor and critic read the
sentence through separate encoders (the default) or through the critic's one.

With an :class:`ObjectLayout` (``architecture: objects``) a :class:`SceneReader` first picks the object the
sentence names by attention, and the 128-unit layer reads the arm and that object only. Which object is
named is then a match between the sentence and each object's features, made with the same weights for
every object, rather than a three-way product of sentence, colour slot and position slot that a flat layer
must assemble for each slot separately.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch
import torch.nn.functional as F
from torch import nn

if TYPE_CHECKING:
    from lanrocli.agent.encoder import LanguageEncoder


@dataclass(frozen=True)
class ObjectLayout:
    """How a flat observation splits into the arm's features and ``slots`` objects' features of ``object``
    numbers each (``arm + slots * object`` in all). A slot whose features are all zero holds no object."""

    arm: int
    object: int
    slots: int

    @property
    def size(self) -> int:
        return self.arm + self.slots * self.object

    def split(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """[B, N] -> the arm's [B, arm] and the objects' [B, slots, object]."""
        return obs[:, : self.arm], obs[:, self.arm :].reshape(obs.shape[0], self.slots, self.object)

    def present(self, raw_obs: torch.Tensor) -> torch.Tensor:
        """bool [B, slots]: which slots hold an object, read from the observation before normalisation."""
        return self.split(raw_obs)[1].ne(0).any(dim=2)


class EnsembleLinear(nn.Module):
    """``n`` independent linear layers evaluated in one batched matmul, so two critics cost one call.

    Input [n, B, in] (or [B, in], shared by all members), output [n, B, out]. Each member is initialised
    like :class:`torch.nn.Linear`.
    """

    def __init__(self, n: int, in_features: int, out_features: int) -> None:
        super().__init__()
        bound = 1.0 / math.sqrt(in_features)
        self.weight = nn.Parameter(torch.empty(n, in_features, out_features).uniform_(-bound, bound))
        self.bias = nn.Parameter(torch.empty(n, 1, out_features).uniform_(-bound, bound))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.dim() == 2:
            x = x.expand(self.weight.shape[0], *x.shape)
        return torch.baddbmm(self.bias, x, self.weight)


class SceneReader(nn.Module):
    """Reads the object a sentence names out of a scene of objects.

    Each object's features give a key, the sentence summary gives a query, and a softmax over the present
    objects of their dot products weighs the objects; the weighted sum of their features is the named
    object as the sentence picks it (by colour and shape for a plain instruction, the corrected object
    after a correction, the one left after a negation). The layers that follow see the named object's
    position and offset from the hand directly, as in a scene of one object. Empty slots get no weight.

    The other objects are left out, so the motor layers learn one scene, whichever object is named.

    ``members`` independent readers run together, one per critic of an ensemble; the output is
    [members, B, arm + object]: the arm's features, then the named object's.
    """

    def __init__(self, members: int, layout: ObjectLayout, language_size: int, width: int) -> None:
        super().__init__()
        self.layout = layout
        self.key = EnsembleLinear(members, layout.object, width)
        self.query = EnsembleLinear(members, language_size, width)
        self.members = members
        self.output_size = layout.arm + layout.object

    def scores(self, obs: torch.Tensor, language: torch.Tensor, present: torch.Tensor) -> torch.Tensor:
        """[members, B, slots]: how strongly the sentence points at each object, as logits of the
        attention weights (empty slots at the dtype's minimum)."""
        objects = self.layout.split(obs)[1]
        keys = self.key(objects.reshape(-1, objects.shape[-1])).reshape(self.members, *present.shape, -1)
        # Products and sums rather than einsum, which on CPU becomes batched matmuls of one row each.
        scores = (keys * self.query(language).unsqueeze(2)).sum(dim=-1) / math.sqrt(keys.shape[-1])
        return scores.masked_fill(~present, torch.finfo(scores.dtype).min)

    def forward(
        self,
        obs: torch.Tensor,
        language: torch.Tensor,
        present: torch.Tensor | None,
        scores: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """``scores``: :meth:`scores` of these arguments, when the caller has computed them already."""
        assert present is not None, "an object-wise network needs to know which slots hold objects"
        arm, objects = self.layout.split(obs)
        weights = (self.scores(obs, language, present) if scores is None else scores).softmax(dim=-1)
        named = (weights.unsqueeze(-1) * objects).sum(dim=-2)
        return torch.cat([arm.expand(self.members, -1, -1), named], dim=2)


def attention_loss(
    readers: Sequence[torch.Tensor | None], label: torch.Tensor, labelled: bool, weight: float
) -> torch.Tensor:
    """The grounding loss: the sum over ``readers`` (each a network's attention logits [members, B, slots]) of
    the cross-entropy of each member's attention against the object that a transition's sentence names
    (``label`` [B], -1 where none is known), averaged over the labelled rows; zero without object-wise readers
    (None), with a weight of 0 or without a labelled row (``labelled``, known to the caller without reading
    ``label``), so that it costs nothing then."""
    loss = torch.zeros((), device=label.device)
    if weight == 0.0 or not labelled:
        return loss
    for scores in readers:
        if scores is not None:
            loss = loss + F.cross_entropy(scores.flatten(0, 1), label.repeat(scores.shape[0]), ignore_index=-1)
    return loss


def _mlp(input_size: int, hidden_size: int, depth: int) -> nn.Sequential:
    layers: list[nn.Module] = []
    for _ in range(depth):
        layers += [nn.Linear(input_size, hidden_size), nn.ReLU()]
        input_size = hidden_size
    return nn.Sequential(*layers)


class Actor(nn.Module):
    """A Gaussian policy squashed by tanh into the action box [-1, 1].

    ``encoder`` is ``None`` when the actor reads the critic's sentence summary instead of its own. With a
    ``layout`` the observation is read object by object (see the module's docstring), and ``present``
    must be given to every call; without ``sentence_in_trunk`` the sentence then acts through the
    attention alone (:attr:`SACSettings.sentence_in_trunk`).
    """

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        encoder: LanguageEncoder | None,
        language_size: int,
        obs_size: int,
        hidden_size: int,
        depth: int,
        log_std_min: float,
        log_std_max: float,
        layout: ObjectLayout | None = None,
        sentence_in_trunk: bool = True,
    ) -> None:
        super().__init__()
        self.encoder = encoder
        self.reader = None if layout is None else SceneReader(1, layout, language_size, obs_size)
        self.obs_layer = nn.Linear(obs_dim if self.reader is None else self.reader.output_size, obs_size)
        self.sentence_in_trunk = sentence_in_trunk
        body_input = obs_size + (language_size if sentence_in_trunk else 0)
        self.body = _mlp(body_input, hidden_size, depth)
        body_size = hidden_size if depth > 0 else body_input
        self.mean = nn.Linear(body_size, action_dim)
        self.log_std = nn.Linear(body_size, action_dim)
        self.log_std_min = log_std_min
        self.log_std_max = log_std_max

    def forward(
        self,
        obs: torch.Tensor,
        language: torch.Tensor,
        present: torch.Tensor | None = None,
        scores: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The mean and log standard deviation of the Gaussian before the squashing. ``scores``: the
        reader's attention logits for these arguments, when the caller has them already."""
        if self.reader is not None:
            obs = self.reader(obs, language, present, scores)[0]
        observed = F.relu(self.obs_layer(obs))
        h = self.body(torch.cat([observed, language], dim=1) if self.sentence_in_trunk else observed)
        log_std = self.log_std(h).clamp(self.log_std_min, self.log_std_max)
        return self.mean(h), log_std

    def sample(
        self,
        obs: torch.Tensor,
        language: torch.Tensor,
        noise: torch.Tensor,
        present: torch.Tensor | None = None,
        scores: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """A reparameterised action in [-1, 1] and its log-probability under the squashed Gaussian, from the
        standard normal ``noise`` (the action's shape). The caller draws it from the agent's own generator,
        whose state is saved with the agent, so a resumed run draws the same actions."""
        mean, log_std = self(obs, language, present, scores)
        u = mean + log_std.exp() * noise
        gaussian_log_prob = (-0.5 * noise.pow(2) - log_std - 0.5 * math.log(2 * math.pi)).sum(dim=1)
        # Change of variables for a = tanh(u): log|da/du| = log(1 - tanh(u)^2), written in a form that
        # stays finite when tanh(u) saturates at +-1.
        log_det = (2.0 * (math.log(2.0) - u - F.softplus(-2.0 * u))).sum(dim=1)
        return torch.tanh(u), gaussian_log_prob - log_det

    def mode(self, obs: torch.Tensor, language: torch.Tensor, present: torch.Tensor | None = None) -> torch.Tensor:
        """The deterministic action for evaluation: the squashed mean."""
        mean, _ = self(obs, language, present)
        return torch.tanh(mean)


class Critic(nn.Module):
    """``n_critics`` Q networks (one, or two for clipped double Q) evaluated together.

    Each member has its own observation layer and hidden layers; they read the same sentence summary, from
    the critic's ``encoder``. With a ``layout`` each member has its own :class:`SceneReader` and reads the
    arm and the object the sentence names (see the module's docstring).
    """

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        encoder: LanguageEncoder,
        obs_size: int,
        hidden_size: int,
        depth: int,
        n_critics: int,
        layout: ObjectLayout | None = None,
        sentence_in_trunk: bool = True,
    ) -> None:
        super().__init__()
        self.encoder = encoder
        self.reader = None if layout is None else SceneReader(n_critics, layout, encoder.output_size, obs_size)
        obs_input = obs_dim if self.reader is None else self.reader.output_size
        self.obs_layer = EnsembleLinear(n_critics, obs_input, obs_size)
        self.sentence_in_trunk = sentence_in_trunk
        input_size = obs_size + (encoder.output_size if sentence_in_trunk else 0) + action_dim
        layers: list[nn.Module] = []
        for _ in range(depth):
            layers += [EnsembleLinear(n_critics, input_size, hidden_size), nn.ReLU()]
            input_size = hidden_size
        self.body = nn.Sequential(*layers)
        self.q = EnsembleLinear(n_critics, input_size, 1)
        self.n_critics = n_critics
        self.action_dim = action_dim

    def forward(
        self, obs: torch.Tensor, language: torch.Tensor, action: torch.Tensor, present: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Q values of shape [n_critics, B]."""
        return self.value(self.observe(obs, language, present), action)

    def observe(
        self,
        obs: torch.Tensor,
        language: torch.Tensor,
        present: torch.Tensor | None = None,
        scores: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Everything each member computes before it sees the action: the first layer after the observation
        layer, applied to the observation's features and the sentence summary (its action columns left out).
        ``scores``: the readers' attention logits for these arguments, when the caller has them already.

        Split from :meth:`value` so that an update that judges two actions in the same states (the stored
        one and the policy's) reads the states once: the policy's action then costs a product with the
        action's few columns instead of the whole layer, forward and backward.
        """
        if self.reader is not None:
            obs = self.reader(obs, language, present, scores)
        observed = F.relu(self.obs_layer(obs))
        first = self._first_layer()
        state = (
            torch.cat([observed, language.expand(self.n_critics, -1, -1)], dim=2)
            if self.sentence_in_trunk
            else observed
        )
        return torch.baddbmm(first.bias, state, first.weight[:, : -self.action_dim])

    def value(self, observed: torch.Tensor, action: torch.Tensor, frozen: bool = False) -> torch.Tensor:
        """Q values [n_critics, B] of ``action`` in the states :meth:`observe` read as ``observed``. ``frozen``:
        the weights read as constants, so that the values' gradient reaches ``action`` and ``observed`` alone
        (how the actor's loss judges the policy's action without training the critic)."""

        def weights(layer: EnsembleLinear) -> tuple[torch.Tensor, torch.Tensor]:
            return (layer.weight.detach(), layer.bias.detach()) if frozen else (layer.weight, layer.bias)

        h = torch.baddbmm(
            observed, action.expand(self.n_critics, -1, -1), weights(self._first_layer())[0][:, -self.action_dim :]
        )
        if len(self.body) > 0:  # the first layer was the body's; the rest of the body and the output follow
            for layer in [*self.body[1:], self.q]:
                if isinstance(layer, EnsembleLinear):
                    weight, bias = weights(layer)
                    h = torch.baddbmm(bias, h, weight)
                else:
                    h = layer(h)
        return h.squeeze(2)

    def _first_layer(self) -> EnsembleLinear:
        """The layer that reads the observation's features, the sentence and the action together."""
        first = self.body[0] if len(self.body) > 0 else self.q
        assert isinstance(first, EnsembleLinear)
        return first
