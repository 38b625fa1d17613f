"""Inverse kinematics for the Panda with the gripper pointing down.

PyBullet's damped least squares converges in a few iterations when its damping is small,
but it ignores the arm's redundancy, so over many steps the elbow wanders far from a
natural pose. Its own null-space variant fixes that but converges slowly. Here the
accurate solution is nudged along the Jacobian's null space towards the neutral pose,
which leaves the end-effector pose unchanged to first order.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from pybullet_utils.bullet_client import BulletClient

IK_ITERATIONS = 4
IK_THRESHOLD = 1e-5
IK_DAMPING = 1e-3
"""Damping of PyBullet's least squares; small, so that a few iterations reach a target a
few centimetres away to within a fraction of a millimetre."""

NULL_SPACE_GAIN = 0.1
"""Fraction of the deviation from the neutral pose removed per step in the null space."""

_REGULARISATION = 1e-6


class ArmIK:
    """Joint angles that put one link at a position with a fixed orientation."""

    def __init__(
        self,
        client: BulletClient,
        body_id: int,
        link: int,
        orientation: tuple[float, float, float, float],
        num_arm_joints: int,
        num_dofs: int,
        rest: Sequence[float],
        lower: Sequence[float],
        upper: Sequence[float],
    ) -> None:
        self._body = body_id
        self._link = link
        self._orientation = orientation
        self._arm = num_arm_joints
        self._rest = np.asarray(rest, dtype=np.float64)
        self._lower = np.asarray(lower, dtype=np.float64)
        self._upper = np.asarray(upper, dtype=np.float64)
        self._damping = [IK_DAMPING] * num_dofs
        self._zeros = [0.0] * num_dofs
        self._regularisation = _REGULARISATION * np.eye(6)
        self._solve = client.calculateInverseKinematics
        self._jacobian = client.calculateJacobian

    def solve(self, target: Sequence[float], joint_positions: Sequence[float]) -> npt.NDArray[np.float64]:
        """Arm joint angles (rad) reaching ``target`` from the current ``joint_positions``.

        ``joint_positions`` lists every movable joint (arm and fingers), as PyBullet's
        Jacobian wants; the arm's part seeds the null-space pull towards the rest pose.
        """
        solution = self._solve(
            self._body,
            self._link,
            target,
            self._orientation,
            jointDamping=self._damping,
            maxNumIterations=IK_ITERATIONS,
            residualThreshold=IK_THRESHOLD,
        )
        arm = np.asarray(solution[: self._arm], dtype=np.float64)
        linear, angular = self._jacobian(
            self._body, self._link, (0.0, 0.0, 0.0), list(joint_positions), self._zeros, self._zeros
        )
        jacobian = np.asarray((*linear, *angular), dtype=np.float64)[:, : self._arm]
        pull = NULL_SPACE_GAIN * (self._rest - np.asarray(joint_positions[: self._arm]))
        gram = jacobian @ jacobian.T + self._regularisation
        arm += pull - jacobian.T @ np.linalg.solve(gram, jacobian @ pull)
        return np.clip(arm, self._lower, self._upper)
