"""Soft Actor-Critic for language-conditioned goals. Its settings, the paper's hyperparameters by default,
live in :mod:`lanrocli.agent.settings`, which needs no torch.

One update, top to bottom: :meth:`SACAgent.learn` samples a batch from the replay buffer, :meth:`SACAgent.update`
turns it into tensors, reads its sentences with the encoders, computes the losses
(:func:`~lanrocli.agent.losses.sac_losses`), takes one backward pass and one Adam step, then moves the target
critic towards the critic.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from torch import nn

from lanrocli.agent.buffer.replay_buffer import ReplayBuffer
from lanrocli.agent.buffer.transitions import Batch
from lanrocli.agent.encoder import LanguageEncoder, distinct_sentences
from lanrocli.agent.losses import Losses, SampledTensors, compiled_losses, sac_losses, update_tensors
from lanrocli.agent.networks import Actor, Critic, ObjectLayout
from lanrocli.agent.noise import restore_generator
from lanrocli.agent.normalizer import RunningNormalizer
from lanrocli.agent.settings import CRITIC_METRICS, UPDATE_METRICS, BufferSettings, SACSettings
from lanrocli.core.choices import ActingAttention

logger = logging.getLogger(__name__)

_FORMAT = 1

POLICY_ONLY_DROPS = ("optimizer", "target_critic", "generator", "generator_device")
"""What :meth:`SACAgent.policy_state_dict` leaves out of the agent's state."""


class SACAgent:
    """The agent: networks, their optimisers, the entropy temperature and the observation normaliser.

    Everything random in it (initial weights, exploration and target-policy noise) derives from ``seed``:
    the weights are drawn inside a forked torch RNG, so building an agent leaves torch's global generator
    untouched, and the noise comes from the agent's own generator, whose state is part of
    :meth:`state_dict`, so a resumed run continues the same stream. A saved state moves between CPU and
    CUDA too, except for that stream, which is specific to its device type (see :meth:`load_state_dict`).
    """

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        vocab_size: int,
        settings: SACSettings | None = None,
        seed: int = 0,
        device: str | torch.device = "cpu",
        layout: ObjectLayout | None = None,
    ) -> None:
        self.settings = s = settings if settings is not None else SACSettings()
        if layout is not None and layout.size != obs_dim:
            raise ValueError(f"the layout describes {layout.size} observation numbers, not {obs_dim}")
        if s.architecture == "objects" and layout is None:
            raise ValueError("architecture 'objects' needs the observation's layout (an ObjectLayout)")
        self.layout = layout if s.architecture == "objects" else None
        self.obs_dim = obs_dim
        self.action_dim = action_dim
        self.vocab_size = vocab_size
        self.device = torch.device(device)
        self.seed = seed
        weight_seed, noise_seed = (int(x) for x in np.random.SeedSequence(seed).generate_state(2))

        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(weight_seed)
            critic_encoder = LanguageEncoder(vocab_size, s.embedding_size, s.language_size)
            actor_encoder = None if s.share_encoder else LanguageEncoder(vocab_size, s.embedding_size, s.language_size)
            self.actor = Actor(
                obs_dim,
                action_dim,
                actor_encoder,
                s.language_size,
                s.obs_size,
                s.hidden_size,
                s.hidden_layers,
                s.log_std_min,
                s.log_std_max,
                self.layout,
                s.sentence_in_trunk,
            ).to(self.device)
            self.critic = Critic(
                obs_dim,
                action_dim,
                critic_encoder,
                s.obs_size,
                s.hidden_size,
                s.hidden_layers,
                s.critics,
                self.layout,
                s.sentence_in_trunk,
            ).to(self.device)
        self.target_critic = copy.deepcopy(self.critic).requires_grad_(False)
        # The layout serves the normaliser whatever the architecture: objects share statistics across slots.
        observed = layout if layout is not None else ObjectLayout(obs_dim, 0, 0)
        self.normalizer = RunningNormalizer(observed, s.obs_clip, s.obs_var_eps).to(self.device)
        self.log_alpha = torch.tensor(math.log(s.alpha), device=self.device, requires_grad=s.autotune_alpha)
        self.target_entropy = s.target_entropy if s.target_entropy is not None else -float(action_dim)

        # One Adam with a parameter group per learner: the losses touch disjoint parameters, so a single
        # step applies all three updates, and fused Adam does it in one kernel, on CPU as on CUDA.
        learners = [list(self.critic.parameters()), list(self.actor.parameters())]
        if s.autotune_alpha:
            learners.append([self.log_alpha])
        groups = [{"params": params, "lr": lr} for params, lr in zip(learners, self._learning_rates())]
        self.optimizer = torch.optim.Adam(groups, fused=True)
        self.generator = torch.Generator(device=self.device)
        self.generator.manual_seed(noise_seed)
        self.updates = 0
        self._compiled: Losses | None = compiled_losses() if s.compile else None

    def _learning_rates(self) -> list[float]:
        """Per parameter group of the optimiser: critic, actor, then the temperature when it is tuned."""
        s = self.settings
        return [s.critic_lr, s.actor_lr, s.alpha_lr][: 3 if s.autotune_alpha else 2]

    # -- acting --------------------------------------------------------------------------------------------

    @property
    def actor_encoder(self) -> LanguageEncoder:
        """The encoder the actor reads sentences with: its own, or the critic's when shared."""
        return self.actor.encoder if self.actor.encoder is not None else self.critic.encoder

    def _acting_inputs(self, obs: Mapping[str, np.ndarray]) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
        """The normalised observations [B, N], which object slots hold objects (None for a flat agent) and the
        actor's summaries of the sentences [B, size]."""
        raw = torch.as_tensor(np.asarray(obs["observation"]), device=self.device, dtype=torch.float32)
        raw = raw.reshape(-1, self.obs_dim)
        tokens = torch.as_tensor(np.asarray(obs["instruction"]), device=self.device, dtype=torch.int64)
        present = None if self.layout is None else self.layout.present(raw)
        return self.normalizer(raw), present, self.actor_encoder(tokens.reshape(raw.shape[0], -1))

    @torch.no_grad()
    def act(self, obs: Mapping[str, np.ndarray], deterministic: bool = False) -> np.ndarray:
        """Actions in [-1, 1] for a batch ``{"observation": [B, N], "instruction": [B, L]}`` (or one
        unbatched observation, answered with one unbatched action)."""
        if deterministic:
            actions = self.act_and_attend(obs)[0]
        else:
            x, present, language = self._acting_inputs(obs)
            noise = torch.randn(x.shape[0], self.action_dim, generator=self.generator, device=self.device)
            actions = self.actor.sample(x, language, noise, present)[0].cpu().numpy()
        return actions[0] if np.asarray(obs["observation"]).ndim == 1 else actions

    @torch.no_grad()
    def act_and_attend(self, obs: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray | None]:
        """For a batch as :meth:`act` takes it: the deterministic actions [B, A] and the actor's attention
        over the object slots [B, slots], summing to 1 over the present objects (None for a flat agent),
        both from one reading of the sentences and the objects."""
        x, present, language = self._acting_inputs(obs)
        if self.actor.reader is None:
            return self.actor.mode(x, language, present).cpu().numpy(), None
        scores = self.actor.reader.scores(x, language, present)
        if self.settings.acting_attention == ActingAttention.ARGMAX:
            # Logits whose softmax is one on each row's highest score: the actor reads that object alone.
            acting = torch.full_like(scores, torch.finfo(scores.dtype).min).scatter(
                -1, scores.argmax(-1, keepdim=True), 0.0
            )
        else:
            acting = scores
        mean, _ = self.actor(x, language, present, acting)
        return torch.tanh(mean).cpu().numpy(), scores[0].softmax(dim=-1).cpu().numpy()

    def act_by(self, attention: ActingAttention) -> None:
        """Read the scene by ``attention`` in deterministic actions from now on (``SACSettings.acting_attention``);
        no weight changes, so an agent trained with one rule can be measured with the other."""
        self.settings = dataclasses.replace(self.settings, acting_attention=ActingAttention(attention).value)

    def update_normalizer(self, observations: np.ndarray) -> None:
        """Add collected observations [n, N] to the normaliser's statistics (not relabelled samples)."""
        self.normalizer.update(observations)

    # -- learning ------------------------------------------------------------------------------------------

    def update(self, batch: Batch) -> dict[str, float]:
        """One SAC update of critic, actor and temperature on ``batch`` (:func:`~lanrocli.agent.losses.sac_losses`),
        then of the target critic; the actor and the temperature learn in every ``SACSettings.actor_every``-th
        update only, and the others report :data:`~lanrocli.agent.settings.CRITIC_METRICS`. All losses are
        computed from the parameters as they were before the update and touch disjoint parameters, so one
        backward pass of their sum and one optimiser step serve all.

        With ``SACSettings.compile`` the losses are compiled where torch can build their kernels; where it
        cannot (on CPU without a working C++ compiler, say), the update warns once and runs eagerly, drawing
        the same noise, rather than a run dying at its first update.
        """
        if self._compiled is not None:
            noise_state = self.generator.get_state()
            try:
                return self._update(batch, self._compiled)
            except Exception as error:  # any failure to compile; a real error is raised again by the eager update
                logger.warning("agent.compile: torch.compile failed here, the update runs eager: %s", error)
                self._compiled = None
                self.generator.set_state(noise_state)
        return self._update(batch, sac_losses)

    def _update(self, batch: Batch, losses: Losses) -> dict[str, float]:
        s = self.settings
        train_actor = self.updates % s.actor_every == 0
        tokens = torch.as_tensor(np.concatenate([batch.instruction, batch.next_instruction]), device=self.device)
        sentences, inverse = distinct_sentences(tokens.to(torch.int64))
        summaries = []
        for encoder in self._update_encoders():
            # The target's reading never learns; the actor's own only in the updates that train the actor.
            learns = encoder is self.critic.encoder or (train_actor and encoder is self.actor.encoder)
            with torch.set_grad_enabled(learns):
                summaries.append(encoder(sentences)[inverse])
        tensors = update_tensors(self, self._sampled_tensors(batch))
        loss, metrics = losses(self, torch.stack(summaries), tensors, batch.labelled, train_actor)
        self.optimizer.zero_grad()
        loss.backward()
        if s.max_grad_norm is not None:
            nn.utils.clip_grad_norm_(self.critic.parameters(), s.max_grad_norm)
            nn.utils.clip_grad_norm_(self.actor.parameters(), s.max_grad_norm)
        self.optimizer.step()
        with torch.no_grad():
            for target, online in zip(self.target_critic.parameters(), self.critic.parameters()):
                target.lerp_(online, 1.0 - s.polyak)
        self.updates += 1
        return dict(zip(UPDATE_METRICS if train_actor else CRITIC_METRICS, metrics.tolist()))

    def _sampled_tensors(self, batch: Batch) -> SampledTensors:
        """The batch as tensors, with the policy's noise for the next states and for these, drawn from the
        agent's own stream, so the losses are a function of tensors alone. Both are drawn in every update,
        one that leaves the actor alone too (``actor_every``), so that each update's draws depend on the
        update count only, whatever the setting."""

        def tensor(array: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(array, device=self.device)

        next_noise, noise = (
            torch.randn(batch.obs.shape[0], self.action_dim, generator=self.generator, device=self.device)
            for _ in range(2)
        )
        return SampledTensors(
            observations=tensor(np.concatenate([batch.obs, batch.next_obs])),
            action=tensor(batch.action),
            reward=tensor(batch.reward),
            done=tensor(batch.done),
            label=tensor(batch.label),
            noise=noise,
            next_noise=next_noise,
        )

    def _update_encoders(self) -> list[LanguageEncoder]:
        """The encoders an update reads the sentences with, in the order :func:`sac_losses` takes their
        summaries: the critic's, the actor's own (if it has one), the target critic's."""
        return [
            self.critic.encoder,
            *([self.actor.encoder] if self.actor.encoder is not None else []),
            self.target_critic.encoder,
        ]

    def learn(
        self,
        buffer: ReplayBuffer,
        rng: np.random.Generator,
        n_updates: int,
        sampling: BufferSettings = BufferSettings(),
    ) -> dict[str, float]:
        """``n_updates`` updates on batches sampled (and relabelled) from ``buffer`` as ``sampling`` says;
        returns each metric averaged over the updates that reported it."""
        totals: dict[str, float] = {}
        counts: dict[str, int] = {}
        for _ in range(n_updates):
            batch = buffer.sample(self.settings.batch_size, rng, sampling)
            for name, value in self.update(batch).items():
                totals[name] = totals.get(name, 0.0) + value
                counts[name] = counts.get(name, 0) + 1
        return {name: value / counts[name] for name, value in totals.items()}

    # -- state ---------------------------------------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """Tensors and plain data only, so ``torch.load(..., weights_only=True)`` reads it back."""
        return {
            "format": _FORMAT,
            "obs_dim": self.obs_dim,
            "action_dim": self.action_dim,
            "vocab_size": self.vocab_size,
            "layout": None if self.layout is None else dataclasses.asdict(self.layout),
            "settings": self.settings.to_dict(),
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "target_critic": self.target_critic.state_dict(),
            "normalizer": self.normalizer.state_dict(),
            "log_alpha": self.log_alpha.detach().clone(),
            "optimizer": self.optimizer.state_dict(),
            "seed": self.seed,
            "generator": self.generator.get_state(),
            "generator_device": self.device.type,
            "updates": self.updates,
        }

    def policy_state_dict(self) -> dict[str, Any]:
        """What acting needs, and no more: :meth:`state_dict` without the optimiser's moments, the target
        critic, the noise stream and, unless the actor reads the sentence with the critic's encoder
        (``share_encoder``), the critic. An agent loaded from it acts exactly as the whole one; its critic,
        where left out, is untrained."""
        state = self.state_dict()
        for name in (*POLICY_ONLY_DROPS, *(() if self.settings.share_encoder else ("critic",))):
            del state[name]
        return state

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore what :meth:`state_dict` saved into an agent of the same dimensions and architecture.

        The other settings (learning rates, gamma, relabelling, ...) stay this agent's, so a run may change
        them between stages and still continue from the saved weights and optimiser moments.

        Tensors land on this agent's device whichever device saved them. The noise generator's state does
        not travel: a CPU generator keeps a Mersenne Twister, a CUDA one a seed and an offset, and neither
        can continue the other's stream. An agent loaded on another device type than the one that saved it
        therefore starts a new stream, seeded from its seed and update count so that the same checkpoint
        loaded the same way gives the same numbers, and logs a warning saying so.
        """
        if state["format"] != _FORMAT:
            raise ValueError(f"agent state format {state['format']} is not {_FORMAT}")
        saved = SACSettings.from_dict(state["settings"])
        layout = None if self.layout is None else dataclasses.asdict(self.layout)
        if state["layout"] != layout:
            raise ValueError(f"the saved agent reads observations laid out as {state['layout']}, this one {layout}")
        for name in ("obs_dim", "action_dim", "vocab_size"):
            if state[name] != getattr(self, name):
                raise ValueError(f"the saved agent has {name} {state[name]}, this one {getattr(self, name)}")
        for name in SACSettings.ARCHITECTURE:
            if getattr(saved, name) != getattr(self.settings, name):
                raise ValueError(
                    f"the saved agent has settings {name}={getattr(saved, name)!r}, this one "
                    f"{getattr(self.settings, name)!r}; build it with SACAgent.from_state_dict"
                )
        self.actor.load_state_dict(state["actor"])
        if "critic" in state:
            self.critic.load_state_dict(state["critic"])
            self.target_critic.load_state_dict(state.get("target_critic", state["critic"]))
        self.normalizer.load_state_dict(state["normalizer"])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        self.updates = int(state["updates"])
        if "optimizer" not in state:  # a policy alone (policy_state_dict): nothing of training to restore
            return
        self.optimizer.load_state_dict(state["optimizer"])
        for group, lr in zip(self.optimizer.param_groups, self._learning_rates()):
            group["lr"] = lr
        restore_generator(self.generator, state, self.device.type, self.seed, self.updates)

    @classmethod
    def from_state_dict(cls, state: Mapping[str, Any], device: str | torch.device = "cpu") -> SACAgent:
        """An agent rebuilt from its saved dimensions, settings and seed, then loaded."""
        agent = cls(
            state["obs_dim"],
            state["action_dim"],
            state["vocab_size"],
            SACSettings.from_dict(state["settings"]),
            seed=int(state["seed"]),
            device=device,
            layout=RunningNormalizer.saved_layout(state["normalizer"]),
        )
        agent.load_state_dict(state)
        return agent
