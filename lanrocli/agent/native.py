"""The GRU's word-by-word loops in C++ (``gru_steps.cpp``), built the first time a process needs them.

An update reads its batch's sentences one word at a time, a few hundred small tensor operations whose cost
on CPU is mostly the Python interpreter's, not the arithmetic. The C++ loops make the same ATen calls as
:func:`lanrocli.agent.gru.forward_steps` and :func:`~lanrocli.agent.gru.backward_steps`, in the same order,
so they give the same numbers bit for bit (a test holds them to it): choosing between the two changes how
fast an update runs, never what it computes. That is why a machine that cannot build them (no C++
compiler) trains on with the Python loops after one warning instead of stopping.

``torch.utils.cpp_extension`` builds the library with the machine's C++ compiler and ninja into torch's
extension folder (``~/.cache/torch_extensions`` unless ``TORCH_EXTENSIONS_DIR`` says otherwise), once per
machine, torch version and copy of the source; later processes load it in well under a second, and processes that start at once
(a sweep's trials) wait for one build under torch's file lock.
"""

from __future__ import annotations

import functools
import hashlib
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch

SOURCE = Path(__file__).with_name("gru_steps.cpp")
LIBRARY = "lanro_gru"  # the operator namespace gru_steps.cpp registers: torch.ops.lanro_gru


@dataclass(frozen=True)
class Steps:
    """A GRU's forward and backward loops, with :func:`lanrocli.agent.gru.forward_steps`' and
    :func:`~lanrocli.agent.gru.backward_steps`' signatures."""

    forward: Callable[..., list[torch.Tensor]]
    backward: Callable[..., list[torch.Tensor]]


@functools.cache
def native_steps() -> Steps | None:
    """The C++ loops, built or loaded once per process; None, after a warning that says why, where they
    cannot be built."""
    from torch.utils import cpp_extension  # imports setuptools: only when needed

    # One build per source text and place: two installs (a checkout and a wheel) would otherwise take turns
    # rebuilding the one folder, each finding the other's build made from another path.
    digest = hashlib.sha256(SOURCE.read_bytes() + str(SOURCE).encode()).hexdigest()[:12]
    try:
        cpp_extension.load(
            name=f"{LIBRARY}_{digest}", sources=[str(SOURCE)], extra_cflags=["-O3", "-ffp-contract=off"], is_python_module=False
        )
    except (OSError, RuntimeError, ImportError) as error:  # no compiler, no ninja, a failed build
        reason = " ".join(str(error).split())[:300]
        warnings.warn(
            f"lanro could not build its C++ GRU steps ({reason}); updates read sentences with the Python "
            "steps instead, which give the same numbers more slowly. To build them, install a C++ compiler "
            "and ninja (Debian: apt-get install g++ ninja-build) and start again.",
            RuntimeWarning,
            stacklevel=2,
        )
        return None
    operators = getattr(torch.ops, LIBRARY)
    return Steps(operators.forward, operators.backward)
