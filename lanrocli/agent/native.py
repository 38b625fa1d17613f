"""This package's C++, built the first time a process needs it: an update's reading of its sentences
(``gru_steps.cpp``) and the replay of its recorded operations (``replay.cpp``, :mod:`lanrocli.agent.replay`).

An update reads its batch's sentences one word at a time: a few hundred small tensor operations whose cost
on CPU is mostly dispatch, allocation and the Python interpreter, not arithmetic. :func:`native_reader`
gives the whole of :func:`lanrocli.agent.encoder.encode` (finding the distinct sentences, the GRUs' steps,
their backward pass) as one C++ call each way. It makes the same ATen calls where rounding is not plain
IEEE arithmetic and the same roundings where it is, so it gives the Python's numbers bit for bit (a test
holds it to that): whether a machine can build it changes how fast an update runs, never what it computes.
The replay is the same kind of guest. That is why a machine that cannot build them (no C++ compiler, no
ninja) trains on in Python after one warning instead of stopping.

``torch.utils.cpp_extension`` builds each library with the machine's C++ compiler and ninja into torch's
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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

TORCH_LOCK = "lock"  # the file torch.utils.cpp_extension makes in a build folder while it builds or loads
BUILD_LOCK = "lanro.lock"  # the file whose OS lock lanro holds around that


@dataclass(frozen=True)
class Library:
    """One C++ source of the package: ``name`` prefixes its builds' names; ``what`` and ``instead`` say, in the
    warning of a machine that cannot build it, what it is and what an update does without it."""

    source: str
    name: str
    what: str
    instead: str
    python_module: bool = False

    @property
    def path(self) -> Path:
        return Path(__file__).with_name(self.source)


READING = Library(
    "gru_steps.cpp", "lanro_gru", "C++ reading of sentences", "updates read them in Python instead"
)  # its name is also the operator namespace it registers: torch.ops.lanro_gru
REPLAY = Library(
    "replay.cpp", "lanro_replay", "C++ replay of an update's operations", "updates run them from Python instead",
    python_module=True,
)

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
        operators = getattr(torch.ops, READING.name)
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
        operators = getattr(torch.ops, READING.name)
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
def library_name(library: Library = READING) -> str:
    """One build per source text and place: two installs (a checkout and a wheel) would otherwise take turns
    rebuilding the one folder, each finding the other's build made from another path. Read once per process."""
    return f"{library.name}_{hashlib.sha256(library.path.read_bytes() + str(library.path).encode()).hexdigest()[:12]}"


def build_folder(library: Library = READING) -> Path:
    """Where torch builds and keeps ``library`` (made if missing)."""
    from torch.utils import cpp_extension

    return Path(cpp_extension._get_build_directory(library_name(library), verbose=False))


@functools.cache
def load(library: Library) -> Any:
    """``library`` built or loaded once per process (its Python module, or True for one that registers
    operators only); None, after a warning that says why, where it cannot be built."""
    from torch.utils import cpp_extension  # imports setuptools: only when needed

    name = library_name(library)
    try:
        folder = build_folder(library)
        # torch's own lock is a file that a process killed while holding it leaves behind, and every later
        # load would wait for it for ever. An OS lock dies with its process: whoever holds this one knows that
        # no other lanro process is building or loading, so a file of torch's found then is stale.
        with open(folder / BUILD_LOCK, "a") as guard:
            fcntl.flock(guard, fcntl.LOCK_EX)
            (folder / TORCH_LOCK).unlink(missing_ok=True)
            module = cpp_extension.load(
                name=name, sources=[str(library.path)], extra_cflags=["-O3", "-ffp-contract=off"],
                is_python_module=library.python_module,
            )
    except (OSError, RuntimeError, ImportError) as error:  # no compiler, no ninja, a failed build
        reason = " ".join(str(error).split())[-300:]  # a failed build's last words are its compiler's
        warnings.warn(
            f"lanro could not build its {library.what} ({reason}); {library.instead}, which gives the same numbers "
            "more slowly. To build it, install a C++ compiler and ninja (Debian: apt-get install g++ ninja-build) "
            "and start again.",
            RuntimeWarning,
            stacklevel=3,
        )
        return None
    return module if library.python_module else True


@functools.cache
def native_reader() -> Reader | None:
    """The C++ reading for CPU tensors, built or loaded once per process; None where it cannot be built."""
    return None if load(READING) is None else _read
