"""A running mean and variance of the observations, so the networks see inputs of unit scale."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from torch import nn

from lanrocli.agent.networks import ObjectLayout

_LAYOUT_KEY = "_extra_state"  # where a module's state dict keeps what get_extra_state returns


class RunningNormalizer(nn.Module):
    """Normalises observations by the mean and variance of every observation collected so far.

    Each arm feature has its own statistics; each object feature has one set shared by all object slots,
    gathered over the objects present only (:meth:`ObjectLayout.present`, the rule the networks mask slots
    by). Statistics per slot would make the same object normalise to different numbers in different
    slots: a slot left empty through a curriculum's first stages holds the statistics of zeros when a later
    stage fills it, which breaks the order invariance of the object-wise networks and hands the flat one a
    different input for the same scene. Counting empty slots would likewise pull every object's mean
    towards zero by how often scenes have fewer objects than slots. Empty slots stay exactly zero after
    normalisation, so "no object" reads the same whatever the statistics. An observation without objects
    is described by ``ObjectLayout(size, 0, 0)``: then every feature is an arm feature.

    The statistics are buffers, so they move with the agent to its device and travel in its state dict,
    together with the layout they were gathered under (loading checks it). They accumulate in float64:
    after a million observations a float32 running mean stops moving. Only observations the agent actually
    collected should be fed to :meth:`update`; relabelled batches only change sentences, and counting an
    observation twice would bias the statistics towards the transitions that happen to be sampled.
    """

    def __init__(self, layout: ObjectLayout, clip: float, eps: float) -> None:
        super().__init__()
        self.layout = layout
        self.clip = clip
        self.eps = eps
        features = layout.arm + layout.object
        # Arm features first, then the object features: the statistics of one arm and one object.
        self.register_buffer("count", torch.zeros(features, dtype=torch.float64))
        self.register_buffer("mean", torch.zeros(features, dtype=torch.float64))
        self.register_buffer("var", torch.ones(features, dtype=torch.float64))
        # The statistics spread over every slot of the observation, in float32 as the agent observes, so that
        # a forward pass (every act and every update) is a subtraction and a product, not a recomputation.
        self.register_buffer("shift", torch.zeros(layout.size), persistent=False)
        self.register_buffer("scale", torch.ones(layout.size), persistent=False)
        self._refresh()

    @torch.no_grad()
    def update(self, observations: np.ndarray | torch.Tensor) -> None:
        """Merge a batch of raw observations [n, size] into the statistics."""
        x = torch.as_tensor(observations, device=self.mean.device).to(torch.float64).reshape(-1, self.layout.size)
        arm, objects = self.layout.split(x)
        self._merge(slice(0, self.layout.arm), arm)
        self._merge(slice(self.layout.arm, None), objects[self.layout.present(x)])
        self._refresh()

    def _merge(self, features: slice, values: torch.Tensor) -> None:
        """Merge rows ``values`` [m, k] into the statistics of ``features`` (Chan et al.'s parallel update).

        Arm and object features see different numbers of values (one arm per observation, as many objects
        as are present), hence a count per feature.
        """
        m = values.shape[0]
        if m == 0:
            return
        count, mean, var = self.count[features], self.mean[features], self.var[features]
        batch_mean = values.mean(dim=0)
        batch_var = values.var(dim=0, unbiased=False)
        total = count + m
        delta = batch_mean - mean
        var.copy_((var * count + batch_var * m + delta.pow(2) * count * m / total) / total)
        mean.add_(delta * m / total)
        count.copy_(total)

    @torch.no_grad()
    def _refresh(self) -> None:
        """Spread the statistics over the observation's width, as :meth:`forward` reads them."""
        arm = self.layout.arm

        def widen(stat: torch.Tensor) -> torch.Tensor:
            return torch.cat([stat[:arm], stat[arm:].repeat(self.layout.slots)])

        self.shift.copy_(widen(self.mean))
        self.scale.copy_(torch.rsqrt(widen(self.var) + self.eps))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Raw observations [B, size] -> normalised and clipped, with empty slots left at zero."""
        out = ((obs - self.shift.to(obs.dtype)) * self.scale.to(obs.dtype)).clamp_(-self.clip, self.clip)
        if self.layout.slots > 0:
            objects = out[:, self.layout.arm :].view(-1, self.layout.slots, self.layout.object)
            objects.mul_(self.layout.present(obs).unsqueeze(2))
        return out

    def get_extra_state(self) -> dict[str, int]:
        return dataclasses.asdict(self.layout)

    def set_extra_state(self, state: Any) -> None:
        if state != self.get_extra_state():
            raise ValueError(
                f"the saved observation statistics were gathered under the layout {state}, "
                f"this normaliser's is {self.get_extra_state()}"
            )

    def _load_from_state_dict(
        self,
        state_dict: Mapping[str, Any],
        prefix: str,
        local_metadata: dict[str, Any],
        strict: bool,
        missing_keys: list[str],
        unexpected_keys: list[str],
        error_msgs: list[str],
    ) -> None:
        # The layout is checked before any statistic is copied, so a mismatched state leaves this one whole.
        self.set_extra_state(_saved_layout_entry(state_dict, prefix))
        super()._load_from_state_dict(
            state_dict, prefix, local_metadata, strict, missing_keys, unexpected_keys, error_msgs
        )
        self._refresh()

    @staticmethod
    def saved_layout(state: Mapping[str, Any]) -> ObjectLayout:
        """The layout a saved normaliser state (its :meth:`state_dict`) was gathered under, to build one that
        loads it."""
        return ObjectLayout(**_saved_layout_entry(state, ""))


def _saved_layout_entry(state: Mapping[str, Any], prefix: str) -> dict[str, int]:
    """The saved layout, or a clear error for a state written when statistics were kept per slot."""
    entry = state.get(prefix + _LAYOUT_KEY)
    if entry is None:
        raise ValueError(
            "the saved observation statistics carry no layout: they were written when every object slot kept "
            "its own statistics, which this version cannot load"
        )
    return dict(entry)
