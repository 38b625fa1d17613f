"""Adam's step as two tensor calls per parameter group, without ``torch.optim``'s per-step Python.

``torch.optim.Adam(fused=True)`` steps a group's parameters in one kernel, but on CPU reaching it (hooks,
grouping by device and type, checks, the profiler's annotations) costs more than the kernel. :func:`adam_step`
calls the same kernel with the same arguments, so it changes no number; the optimiser keeps the moments, the
learning rates and ``state_dict``, and takes every parameter's first step itself, which creates its moments.
"""

from __future__ import annotations

import torch


def adam_step(optimizer: torch.optim.Adam) -> None:
    """One step of ``optimizer``, a plain Adam (no amsgrad, not maximising) built with ``fused=True``, on the
    gradients its parameters hold."""
    groups = [[p for p in group["params"] if p.grad is not None] for group in optimizer.param_groups]
    if not all(p in optimizer.state for params in groups for p in params):
        optimizer.step()
        return
    for group, params in zip(optimizer.param_groups, groups):
        if not params:
            continue
        states = [optimizer.state[p] for p in params]
        steps = [state["step"] for state in states]
        torch._foreach_add_(steps, 1)
        beta1, beta2 = group["betas"]
        torch._fused_adam_(
            params,
            [p.grad for p in params],
            [state["exp_avg"] for state in states],
            [state["exp_avg_sq"] for state in states],
            [],
            steps,
            amsgrad=False,
            lr=group["lr"],
            beta1=beta1,
            beta2=beta2,
            weight_decay=group["weight_decay"],
            eps=group["eps"],
            maximize=False,
        )
