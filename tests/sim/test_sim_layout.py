from __future__ import annotations

import numpy as np
import pybullet
from hypothesis import given
from hypothesis import strategies as st

from lanrocli.sim import CONTROL_DT, OBJECT_AREA, SUBSTEPS, WORKSPACE, World
from lanrocli.sim.panda import URDF

coordinate = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False)


@given(st.tuples(coordinate, coordinate, coordinate))
def test_workspace_clip_lands_inside(point: tuple[float, float, float]) -> None:
    clipped = WORKSPACE.clip(point)
    assert WORKSPACE.contains(clipped)
    if WORKSPACE.contains(point):
        np.testing.assert_array_equal(clipped, point)


def test_workspace_surrounds_the_object_area() -> None:
    for axis in (0, 1):
        assert WORKSPACE.low[axis] <= OBJECT_AREA.low[axis] - 0.05
        assert WORKSPACE.high[axis] >= OBJECT_AREA.high[axis] + 0.05
    assert 0.0 < WORKSPACE.low[2] < 0.02


def test_single_substepped_call_matches_explicit_substeps() -> None:
    """The stepping scheme is only valid if scaled motor limits reproduce 20 plain steps."""
    single, explicit = World(), World()
    try:
        explicit.client.setPhysicsEngineParameter(fixedTimeStep=CONTROL_DT / SUBSTEPS, numSubSteps=0)
        joints = list(range(7))
        bodies = [w.client.loadURDF(URDF, basePosition=[-0.5, 0, 0], useFixedBase=True) for w in (single, explicit)]
        targets = [0.3, 0.5, -0.2, -1.5, 0.1, 1.8, 0.4]
        weak = [5.0] * 7  # weak enough that the limits decide the motion
        single.client.setJointMotorControlArray(
            bodies[0],
            joints,
            pybullet.POSITION_CONTROL,
            targetPositions=targets,
            forces=[f * single.motor_force_scale for f in weak],
        )
        explicit.client.setJointMotorControlArray(
            bodies[1], joints, pybullet.POSITION_CONTROL, targetPositions=targets, forces=weak
        )
        for _ in range(10):
            single.step_physics()
            for _ in range(SUBSTEPS):
                explicit.client.stepSimulation()
        a = [s[0] for s in single.client.getJointStates(bodies[0], joints)]
        b = [s[0] for s in explicit.client.getJointStates(bodies[1], joints)]
        np.testing.assert_allclose(a, b, atol=1e-9)
        assert np.abs(np.subtract(a, targets)).max() > 0.1
    finally:
        single.close()
        explicit.close()
