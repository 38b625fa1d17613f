"""The agent's exploration noise across a save and load: its generator's state is specific to the device
type that drew it (a CPU generator keeps a Mersenne Twister, a CUDA one a seed and an offset)."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

logger = logging.getLogger(__name__)


def restore_generator(
    generator: torch.Generator, state: Mapping[str, Any], device_type: str, seed: int, updates: int
) -> None:
    """Continue the noise stream ``state`` saved on the device type that saved it; on another, start a
    stream derived from the agent's ``seed`` and update count, so that the same checkpoint loaded the same
    way gives the same numbers, and warn that the stream changed."""
    saved = state["generator"].cpu()
    saved_on = state["generator_device"]
    if saved_on == device_type:
        generator.set_state(saved)
        return
    generator.manual_seed(int(np.random.SeedSequence([seed, updates]).generate_state(1)[0]))
    logger.warning(
        "the agent's exploration noise was saved on %s and cannot continue on %s; it restarts from a stream "
        "derived from the agent's seed (%d) and update count (%d)",
        saved_on,
        device_type,
        seed,
        updates,
    )
