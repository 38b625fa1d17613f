from __future__ import annotations

import pytest

from lanrocli.core.rates import PHYSICS_HZ, SUBSTEPS, substeps


def test_physics_rates_split_the_control_step_into_whole_physics_steps() -> None:
    assert substeps(PHYSICS_HZ) == SUBSTEPS == 20
    assert substeps(250) == 10
    for bad in (0, 260, 250.0, True):
        with pytest.raises(ValueError, match="physics_hz must be a whole multiple of 25"):
            substeps(bad)  # type: ignore[arg-type]
