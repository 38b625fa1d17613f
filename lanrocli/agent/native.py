"""An update's reading of its sentences in C++ (``gru_steps.cpp``), built the first time a process needs it.

An update reads its batch's sentences one word at a time: a few hundred small tensor operations whose cost
on CPU is mostly dispatch, allocation and the Python interpreter, not arithmetic. :func:`native_reader`
gives the whole of :func:`lanrocli.agent.encoder.encode` (finding the distinct sentences, the GRUs' steps,
their backward pass) as one C++ call each way. It makes the same ATen calls where rounding is not plain
IEEE arithmetic and the same roundings where it is, so it gives the Python's numbers bit for bit (a test
holds it to that): whether a machine can build it changes how fast an update runs, never what it computes.
That is why a machine that cannot build it (no C++ compiler, no ninja) trains on in Python after one
warning instead of stopping.

``torch.utils.cpp_extension`` builds the library with the machine's C++ compiler and ninja into torch's
extension folder (``~/.cache/torch_extensions`` unless ``TORCH_EXTENSIONS_DIR`` says otherwise), once per
machine, torch version and copy of the source; later processes load it in a fraction of a second, and
processes that start at once (a sweep's trials) wait for one build under an OS lock, which a killed process
cannot leave behind.
"""

from __future__ import annotations

import fcntl
import functools
import hashlib
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

SOURCE = Path(__file__).with_name("gru_steps.cpp")
LIBRARY = "lanro_gru"  # the operator namespace gru_steps.cpp registers: torch.ops.lanro_gru
TORCH_LOCK = "lock"  # the file torch.utils.cpp_extension makes in a build folder while it builds or loads
BUILD_LOCK = "lanro.lock"  # the file whose OS lock lanro holds around that

Reader = Callable[[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, int, int], torch.Tensor]


class _Read(torch.autograd.Function):
    """``torch.ops.lanro_gru.read`` and its backward pass as one differentiable function."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: Any,
        tables: torch.Tensor,
        weight_hh: torch.Tensor,
        bias_hh: torch.Tensor,
        tokens: torch.Tensor,
        pad_id: int,
        trained: int,
    ) -> torch.Tensor:
        operators = getattr(torch.ops, LIBRARY)
        keep = trained > 0 and any(ctx.needs_input_grad[:3])
        summaries, *saved = operators.read(tables, weight_hh, bias_hh, tokens, pad_id, trained, keep)
        if keep and saved:
            ctx.save_for_backward(weight_hh[:trained], *saved)
            ctx.members, ctx.vocab_size = tables.shape[0], tables.shape[1]
        elif keep:  # no sentence had a word: the summaries are zeros that depend on nothing
            ctx.mark_non_differentiable(summaries)
        return summaries

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor | None, ...]:
        operators = getattr(torch.ops, LIBRARY)
        grads = operators.read_backward(grad, *ctx.saved_tensors, ctx.members, ctx.vocab_size)
        return *grads, None, None, None


def _read(
    tables: torch.Tensor, weight_hh: torch.Tensor, bias_hh: torch.Tensor, tokens: torch.Tensor, pad_id: int, trained: int
) -> torch.Tensor:
    """:func:`lanrocli.agent.encoder.encode`'s reading of ``tokens`` [B, L] by the GRUs whose input gates,
    recurrent weights and biases are given, of which the first ``trained`` get gradients (as
    :func:`lanrocli.agent.gru.read_sentences` takes them): [members, B, size]."""
    return _Read.apply(tables, weight_hh, bias_hh, tokens, pad_id, trained if torch.is_grad_enabled() else 0)


@functools.cache
def library_name() -> str:
    """One build per source text and place: two installs (a checkout and a wheel) would otherwise take turns
    rebuilding the one folder, each finding the other's build made from another path. Read once per process."""
    return f"{LIBRARY}_{hashlib.sha256(SOURCE.read_bytes() + str(SOURCE).encode()).hexdigest()[:12]}"


def build_folder() -> Path:
    """Where torch builds and keeps the library (made if missing)."""
    from torch.utils import cpp_extension

    return Path(cpp_extension._get_build_directory(library_name(), verbose=False))


@functools.cache
def native_reader() -> Reader | None:
    """The C++ reading for CPU tensors, built or loaded once per process; None, after a warning that says
    why, where it cannot be built."""
    from torch.utils import cpp_extension  # imports setuptools: only when needed

    name = library_name()
    try:
        folder = build_folder()
        # torch's own lock is a file that a process killed while holding it leaves behind, and every later
        # load would wait for it for ever. An OS lock dies with its process: whoever holds this one knows that
        # no other lanro process is building or loading, so a file of torch's found then is stale.
        with open(folder / BUILD_LOCK, "a") as guard:
            fcntl.flock(guard, fcntl.LOCK_EX)
            (folder / TORCH_LOCK).unlink(missing_ok=True)
            cpp_extension.load(
                name=name, sources=[str(SOURCE)], extra_cflags=["-O3", "-ffp-contract=off"], is_python_module=False
            )
    except (OSError, RuntimeError, ImportError) as error:  # no compiler, no ninja, a failed build
        reason = " ".join(str(error).split())[-300:]  # a failed build's last words are its compiler's
        warnings.warn(
            f"lanro could not build its C++ reading of sentences ({reason}); updates read them in Python "
            "instead, which gives the same numbers more slowly. To build it, install a C++ compiler and ninja "
            "(Debian: apt-get install g++ ninja-build) and start again.",
            RuntimeWarning,
            stacklevel=2,
        )
        return None
    return _read
