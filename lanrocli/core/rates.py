"""The simulation's clock: control actions and physics steps per simulated second.

Apart from the simulation itself, so that settings can check a physics rate without loading PyBullet.
"""

from __future__ import annotations

CONTROL_HZ = 25
"""Control actions per simulated second."""

CONTROL_DT = 1 / CONTROL_HZ
"""Seconds of simulated time per control action (0.04 s)."""

PHYSICS_HZ = 500
"""Default physics rate (Hz); steps this small keep finger-object contacts stable in grasps. A world may run at
another rate (``World(physics_hz=...)``, an environment's ``physics_hz``)."""

SUBSTEPS = PHYSICS_HZ // CONTROL_HZ
"""Physics steps per control action at ``PHYSICS_HZ``."""


def substeps(physics_hz: int) -> int:
    """Physics steps per control action at ``physics_hz``; the rate must split a control step evenly."""
    if (
        isinstance(physics_hz, bool)
        or not isinstance(physics_hz, int)
        or physics_hz < CONTROL_HZ
        or physics_hz % CONTROL_HZ
    ):
        raise ValueError(
            f"physics_hz must be a whole multiple of {CONTROL_HZ} Hz, the control rate, so that a control step "
            f"splits into whole physics steps (for example 250 or {PHYSICS_HZ}); got {physics_hz!r}"
        )
    return physics_hz // CONTROL_HZ
