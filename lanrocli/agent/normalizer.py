"""A running mean and variance of the observations, so the networks see inputs of unit scale."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


class RunningNormalizer(nn.Module):
    """Normalises observations by the mean and variance of every observation collected so far.

    The statistics are buffers, so they move with the agent to its device and travel in its state dict.
    They accumulate in float64: after a million observations a float32 running mean stops moving.
    Only observations the agent actually collected should be fed to :meth:`update`; relabelled batches
    only change sentences, and counting an observation twice would bias the statistics towards the
    transitions that happen to be sampled.
    """

    def __init__(self, size: int, clip: float, eps: float) -> None:
        super().__init__()
        self.clip = clip
        self.eps = eps
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))
        self.register_buffer("mean", torch.zeros(size, dtype=torch.float64))
        self.register_buffer("var", torch.ones(size, dtype=torch.float64))

    @torch.no_grad()
    def update(self, observations: np.ndarray | torch.Tensor) -> None:
        """Merge a batch [n, size] into the statistics (Chan et al.'s parallel variance update)."""
        x = torch.as_tensor(observations, device=self.mean.device).to(torch.float64).reshape(-1, self.mean.shape[0])
        n = x.shape[0]
        if n == 0:
            return
        batch_mean = x.mean(dim=0)
        batch_var = x.var(dim=0, unbiased=False)
        total = self.count + n
        delta = batch_mean - self.mean
        m2 = self.var * self.count + batch_var * n + delta.pow(2) * self.count * n / total
        self.mean += delta * n / total
        self.var.copy_(m2 / total)
        self.count.copy_(total)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        mean = self.mean.to(obs.dtype)
        inv_std = torch.rsqrt(self.var.to(obs.dtype) + self.eps)
        return ((obs - mean) * inv_std).clamp(-self.clip, self.clip)
