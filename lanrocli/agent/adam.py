"""Adam's step as one kernel per parameter group, without ``torch.optim``'s per-step Python.

``torch.optim.Adam(fused=True)`` steps a group's parameters in one kernel, but on CPU reaching it (hooks,
grouping by device and type, checks, the profiler's annotations) costs more than the kernel, as does counting
the step with one addition per parameter's 0-d counter. :class:`AdamStep` calls the same kernel with the same
arguments, so it changes no number; the optimiser keeps the moments, the learning rates and ``state_dict``,
and takes every parameter's first step itself, which creates its moments.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import torch


@dataclass
class _Group:
    """What the kernel takes of one parameter group: its parameters that have gradients and their states'
    tensors. The states' step counters are views into ``counter``, so one addition counts a step for all."""

    params: list[torch.Tensor]
    exp_avg: list[torch.Tensor]
    exp_avg_sq: list[torch.Tensor]
    steps: list[torch.Tensor]
    counter: torch.Tensor

    @classmethod
    def of(cls, state: dict[torch.Tensor, Any], params: list[torch.Tensor]) -> _Group:
        """The group's lists, its states' step counters made views of one tensor (with the values they had)."""
        states = [state[p] for p in params]
        counter = torch.stack([s["step"] for s in states]) if states else torch.zeros(0)
        for index, s in enumerate(states):
            s["step"] = counter[index]
        return cls(params, [s["exp_avg"] for s in states], [s["exp_avg_sq"] for s in states], [s["step"] for s in states], counter)

    def holds(self, state: dict[torch.Tensor, Any], params: list[torch.Tensor]) -> bool:
        """Whether these lists are still the group's: the same parameters have gradients, and the optimiser's
        state is the one they were taken from (``load_state_dict`` puts new tensors there)."""
        return len(params) == len(self.params) and all(
            p is q and state[p]["step"] is step for p, q, step in zip(params, self.params, self.steps)
        )


class AdamStep:
    """Steps ``optimizer``, a plain Adam (no amsgrad, not maximising) built with ``fused=True``, on the
    gradients its parameters hold; a parameter without one is left alone, as torch leaves it."""

    def __init__(self, optimizer: torch.optim.Adam) -> None:
        self.optimizer = optimizer
        self._groups: list[_Group] = []

    def __call__(self) -> None:
        optimizer = self.optimizer
        params = [[p for p in group["params"] if p.grad is not None] for group in optimizer.param_groups]
        if len(params) != len(self._groups) or not all(g.holds(optimizer.state, ps) for g, ps in zip(self._groups, params)):
            if not all(p in optimizer.state for ps in params for p in ps):
                optimizer.step()
                return
            self._groups = [_Group.of(optimizer.state, ps) for ps in params]
        for group, planned in zip(optimizer.param_groups, self._groups):
            if not planned.params:
                continue
            planned.counter.add_(1)
            beta1, beta2 = group["betas"]
            torch._fused_adam_(
                planned.params,
                [p.grad for p in planned.params],
                planned.exp_avg,
                planned.exp_avg_sq,
                [],
                planned.steps,
                amsgrad=False,
                lr=group["lr"],
                beta1=beta1,
                beta2=beta2,
                weight_decay=group["weight_decay"],
                eps=group["eps"],
                maximize=False,
            )

    def __deepcopy__(self, memo: dict[int, Any]) -> AdamStep:
        """The copy's optimiser's; its lists are taken anew at its first step."""
        return AdamStep(copy.deepcopy(self.optimizer, memo))
