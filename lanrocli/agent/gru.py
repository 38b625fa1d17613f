"""Several GRUs stepped together over the same sentences, with back-propagation through time written out.

PyTorch has no fused GRU kernel on CPU: ``nn.GRU`` runs each time step as a handful of small operations and
autograd records every one of them, so reading a batch's sentences was the largest single cost of an update
on CPU. Here:

- the GRUs of the networks that read a batch (critic, actor, target critic) step together, one batched
  product per step;
- a GRU's input depends on the word alone, so a table of each word's input gates (one small product per
  update) replaces a product per word of the batch;
- rows are sorted by length, so each step computes only the sentences that still have words, about half of
  the padded array on reach's instructions;
- the backward pass is the chain rule applied by hand: what does not depend on the incoming gradient is
  computed for all steps at once, leaving three operations per step, and the weight gradient is one product;
- on CPU, where the machine can build it, all of this runs in C++ (``gru_steps.cpp``,
  :mod:`lanrocli.agent.native`) with the same numbers bit for bit: this module is its reference.

What that gains over ``nn.GRU`` is measured in docs/performance.md.

The equations are ``nn.GRU``'s (gates ordered r, z, n in its weights), whose modules still hold the weights:

    r = sigmoid(x W_ir + b_ir + h W_hr + b_hr)
    z = sigmoid(x W_iz + b_iz + h W_hz + b_hz)
    n = tanh(x W_in + b_in + r * (h W_hn + b_hn))
    h' = (1 - z) * n + z * h  =  n + z * (h - n)
"""

from __future__ import annotations

import itertools
from typing import Any

import torch


def _tanh(x: torch.Tensor) -> torch.Tensor:
    """tanh(x) = 2 sigmoid(2x) - 1, written when an older torch's tanh was far slower on CPU than sigmoid. Today's
    is faster, but replacing this changes the last bits of every update and so the runs docs/ quotes: it waits
    for a change that retrains them anyway (docs/lab-notebook.md, update speed)."""
    return torch.sigmoid(2.0 * x) * 2.0 - 1.0


def forward_steps(
    inputs: torch.Tensor,
    weight_hh: torch.Tensor,
    bias_hh: torch.Tensor,
    active: list[int],
    trained: int,
    keep: bool,
) -> list[torch.Tensor]:
    """The state after each row's last step, for rows sorted by length, longest first, so that at step t
    only the first ``active[t]`` rows still read words and each step computes those alone; then, if
    ``keep``, what :func:`backward_steps` needs of the first ``trained`` members (h before each step, r and
    z, n, and h W_hn + b_hn, packed step after step).

    ``inputs`` [members, sum(active), 3 * size] come packed: the rows active at step 0, then those at step 1,
    and so on. ``weight_hh`` [members, 3 * size, size] and ``bias_hh`` [members, 3 * size] as ``nn.GRU``
    holds them. The state is [members, active[0], size]."""
    members, _, gates = inputs.shape
    size, rows = gates // 3, active[0]
    weight_t, bias = weight_hh.transpose(1, 2), bias_hh.unsqueeze(1)
    h = inputs.new_zeros(members, rows, size)
    finished: list[torch.Tensor] = []  # the final states of rows whose sentence has ended, last rows first
    saved: tuple[list[torch.Tensor], ...] = ([], [], [], [])  # h before the step, r and z, n, h W_hn + b_hn
    start = 0
    for k in active:
        if k < h.shape[1]:
            finished.append(h[:, k:])
            h = h[:, :k]
        hidden = torch.baddbmm(bias, h, weight_t)
        x = inputs[:, start : start + k]
        start += k
        hidden_n = hidden[..., 2 * size :]
        rz = torch.sigmoid(x[..., : 2 * size] + hidden[..., : 2 * size])
        n = _tanh(torch.addcmul(x[..., 2 * size :], rz[..., :size], hidden_n))
        if keep:
            for store, value in zip(saved, (h, rz, n, hidden_n)):
                store.append(value[:trained])
        h = torch.addcmul(n, rz[..., size:], h - n)
    last = torch.cat([h, *reversed(finished)], dim=1)
    return [last, *(torch.cat(values, dim=1) for values in saved)] if keep else [last]


def backward_steps(
    grad: torch.Tensor,
    weight_hh: torch.Tensor,
    before: torch.Tensor,
    rz: torch.Tensor,
    n: torch.Tensor,
    hidden_n: torch.Tensor,
    active: list[int],
) -> list[torch.Tensor]:
    """The gradients of :func:`forward_steps`' inputs, recurrent weights and recurrent biases for the
    members it kept, given the gradient of its state and what it kept."""
    grad = grad[: weight_hh.shape[0]]
    members, packed, size = before.shape
    r, z = rz[..., :size], rz[..., size:]
    # What does not depend on the incoming gradient, for all steps at once: the derivatives of h' with
    # respect to the recurrent gate inputs h W_h + b_h (r, z, n), and to n's pre-activation.
    to_n = (1.0 - z) * (1.0 - n * n)
    to_hidden = torch.cat([to_n * hidden_n * r * (1.0 - r), (before - n) * z * (1.0 - z), to_n * r], dim=2)
    to_hidden = to_hidden.view(members, packed, 3, size)
    step_grads: list[torch.Tensor] = []  # the gradient with respect to each step's new state
    hidden_grads: list[torch.Tensor] = []  # ... and to its recurrent gate inputs
    ends = list(itertools.accumulate(active))
    g = grad[:, : active[-1]]
    for t in reversed(range(len(active))):
        k, step = active[t], slice(ends[t] - active[t], ends[t])
        step_grads.append(g)
        hidden_grads.append((to_hidden[:, step] * g.unsqueeze(2)).flatten(2))
        g = torch.baddbmm(g * z[:, step], hidden_grads[-1], weight_hh)  # with respect to h before the step
        if t > 0 and active[t - 1] > k:  # rows whose sentence ended at step t - 1 join
            g = torch.cat([g, grad[:, k : active[t - 1]]], dim=1)
    hidden_all = torch.cat(hidden_grads[::-1], dim=1)  # [members, sum(active), 3 * size]
    grad_n = torch.cat(step_grads[::-1], dim=1) * to_n
    grad_inputs = torch.cat([hidden_all[..., : 2 * size], grad_n], dim=2)
    return [grad_inputs, torch.bmm(hidden_all.transpose(1, 2), before), hidden_all.sum(dim=1)]


class _LastState(torch.autograd.Function):
    """:func:`forward_steps` and :func:`backward_steps` as one differentiable function. Only the first
    ``trained`` members get gradients; the others (a target network) step along in the forward pass alone."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: Any,
        inputs: torch.Tensor,
        weight_hh: torch.Tensor,
        bias_hh: torch.Tensor,
        active: list[int],
        trained: int,
    ) -> torch.Tensor:
        keep = trained > 0 and any(ctx.needs_input_grad)
        last, *saved = forward_steps(inputs, weight_hh, bias_hh, active, trained, keep)
        if keep:
            ctx.save_for_backward(weight_hh[:trained], *saved)
            ctx.active, ctx.frozen = active, inputs.shape[0] - trained
        return last

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, None, None]:
        grads = backward_steps(grad, *ctx.saved_tensors, ctx.active)
        if ctx.frozen:
            grads = [torch.cat([part, part.new_zeros(ctx.frozen, *part.shape[1:])]) for part in grads]
        return *grads, None, None


def read_sentences(
    input_tables: torch.Tensor,
    weight_hh: torch.Tensor,
    bias_hh: torch.Tensor,
    tokens: torch.Tensor,
    pad_id: int,
    trained: int | None = None,
) -> torch.Tensor:
    """The state of ``members`` GRUs after each row's last word, from a zero state.

    ``input_tables``: [members, vocab, 3 * size], each GRU's input gates ``x W_ih + b_ih`` for each word
    (``x`` its embedding). ``weight_hh``: [members, 3 * size, size] and ``bias_hh``: [members, 3 * size],
    as ``nn.GRU`` holds them. ``tokens``: int64 [rows, L], words followed by ``pad_id``. A row without
    words keeps the zero state. Only the first ``trained`` members (all by default) get gradients.
    Returns [members, rows, size].
    """
    members, rows = input_tables.shape[0], tokens.shape[0]
    size = weight_hh.shape[2]
    lengths = (tokens != pad_id).sum(dim=1)
    order = torch.argsort(lengths, descending=True, stable=True)
    steps = torch.arange(tokens.shape[1], device=tokens.device)
    reading = steps.unsqueeze(1) < lengths[order].unsqueeze(0)  # [L, rows]: who reads a word at each step
    active = [k for k in reading.sum(dim=1).tolist() if k > 0]
    if not active:
        return input_tables.new_zeros(members, rows, size)
    inputs = input_tables.index_select(1, tokens[order].t()[reading])
    trained = (members if trained is None else trained) if torch.is_grad_enabled() else 0
    h = _LastState.apply(inputs, weight_hh, bias_hh, active, trained)  # the rows with words, longest first
    h = torch.cat([h, h.new_zeros(members, rows - active[0], size)], dim=1)
    return h.index_select(1, torch.argsort(order))
