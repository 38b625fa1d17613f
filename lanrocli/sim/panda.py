"""The Franka Panda arm, driven by end-effector displacements.

An action moves the end-effector point (between the fingertips) by up to ``MAX_STEP`` per
axis and control step, measured from where the end effector is now; inverse kinematics
turns the target into arm joint positions, keeping the gripper pointing straight down with
the fingers opening along the world y axis.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pybullet

from lanrocli.sim.kinematics import ArmIK
from lanrocli.sim.layout import ROBOT_BASE, WORKSPACE
from lanrocli.sim.world import World

URDF = "franka_panda/panda.urdf"

ARM_JOINTS: tuple[int, ...] = (0, 1, 2, 3, 4, 5, 6)
FINGER_JOINTS: tuple[int, int] = (9, 10)
CONTROLLED_JOINTS: tuple[int, ...] = ARM_JOINTS + FINGER_JOINTS
"""All movable joints, in the order PyBullet's kinematics functions expect them."""

HAND_LINK = 8
LEFT_FINGER_LINK = 9
"""Finger on the world -y side when the gripper points down."""
RIGHT_FINGER_LINK = 10
"""Finger on the world +y side when the gripper points down."""
EE_LINK = 11
"""``panda_grasptarget``: the point between the fingertip pads, 1.1 cm above their tips."""

NEUTRAL_ARM: tuple[float, ...] = (0.0, 0.2678, 0.0, -2.3993, 0.0, 2.6672, 0.7854)
"""Arm joint angles (rad) that put the end effector at (0, 0, 0.10), pointing down.

Ten centimetres above the table, the objects are two or three steps away: an arm that starts there and
moves at random touches some object in about one episode in ten, against one in fifty from 20 cm, and
those touches are what hindsight relabelling learns from."""

DOWN: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
"""End-effector orientation (x y z w): rotated by pi about x, so its z axis points down."""

ARM_TORQUES: tuple[float, ...] = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
"""Torque limits (N m) of the seven arm joints: the real Panda's.

With them the wrist saturates on a full 4 cm step and the end effector lags its target by about 2 cm (it
catches up on the next steps), but contacts stay physical. With 300 N m on every joint the arm tracked to
3 mm, and it also drove its fingers into objects hard enough to fling one off the table in one random
episode in thirty (up to 10 m/s), and shoved touched objects beyond reach's 2.5 cm: random arms touched an
object cleanly in 7 of 100 episodes, against 21 of 100 with these limits, and none was flung. The scripted
oracle solves every task either way.
"""

FINGER_FORCE = 20.0
"""Force limit per finger (N); with friction 1.0 it holds a 0.1 kg object many times over."""

POSITION_GAIN = 0.15
"""Gain of PyBullet's joint position control: a full action then moves the end effector about 3 cm per
step in a straight line (5 cm downwards, where gravity helps the torque-limited wrist); higher gains
overshoot and oscillate."""

MAX_STEP = 0.04
"""Largest end-effector displacement per control step (m) along each axis."""

MAX_FINGER_WIDTH = 0.08
"""Distance between the finger joints when fully open (m); the pads are then 7.1 cm apart."""

FINGER_FRICTION = 1.0

RESET_IK_ROUNDS = 8
"""IK calls that take the arm from the neutral pose to a reset position anywhere in the workspace; eight
reach every corner to within a millimetre."""


@dataclass(frozen=True)
class RobotState:
    """Robot state in the world frame; arrays are read-only.

    ee_position (3,) m and ee_velocity (3,) m/s of the end-effector point; finger_width m
    (distance between the finger joints: 0 closed, 0.08 fully open); joint_positions (9,)
    rad for the seven arm joints then m for the two fingers.
    """

    ee_position: npt.NDArray[np.float64]
    ee_velocity: npt.NDArray[np.float64]
    finger_width: float
    joint_positions: npt.NDArray[np.float64]


@dataclass(frozen=True)
class Contacts:
    """Which robot parts touch each queried body; boolean arrays aligned with the query."""

    left_finger: npt.NDArray[np.bool_]
    right_finger: npt.NDArray[np.bool_]
    hand: npt.NDArray[np.bool_]
    """The hand or either finger (the gripper as a whole)."""
    robot: npt.NDArray[np.bool_]
    """Any link of the robot, arm included."""


def _read_only(array: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    array.flags.writeable = False
    return array


def action_size(gripper: bool) -> int:
    """Length of the action vector: the hand's displacement (dx, dy, dz), and the finger opening with the gripper."""
    return 4 if gripper else 3


class Panda:
    """A fixed-base Panda on the table, controlled by Cartesian end-effector steps.

    With ``gripper=False`` actions have three entries (dx, dy, dz) and the fingers are held
    closed; with ``gripper=True`` a fourth entry in [-1, 1] sets the finger opening from
    closed (-1) to fully open (+1).
    """

    def __init__(self, world: World, gripper: bool = False) -> None:
        self._world = world
        self._gripper = gripper
        client = world.client
        self._client = client
        self.body_id = int(
            client.loadURDF(
                URDF,
                basePosition=ROBOT_BASE,
                useFixedBase=True,
                flags=pybullet.URDF_ENABLE_CACHED_GRAPHICS_SHAPES
                | (0 if world.images else pybullet.URDF_IGNORE_VISUAL_SHAPES),
            )
        )
        arm_infos = [client.getJointInfo(self.body_id, j) for j in ARM_JOINTS]
        self._ik = ArmIK(
            client,
            self.body_id,
            EE_LINK,
            DOWN,
            num_arm_joints=len(ARM_JOINTS),
            num_dofs=len(CONTROLLED_JOINTS),
            rest=NEUTRAL_ARM,
            lower=[info[8] for info in arm_infos],
            upper=[info[9] for info in arm_infos],
        )
        scale = world.motor_force_scale
        self._forces = [torque * scale for torque in ARM_TORQUES] + [FINGER_FORCE * scale] * 2
        self._gains = [POSITION_GAIN] * len(CONTROLLED_JOINTS)
        for finger in FINGER_JOINTS:
            client.changeDynamics(self.body_id, finger, lateralFriction=FINGER_FRICTION)
        self._get_link_state = client.getLinkState
        self._get_joint_states = client.getJointStates
        self._set_motors = client.setJointMotorControlArray
        self._get_contacts = client.getContactPoints
        self._get_closest = client.getClosestPoints
        self._finger_target = 0.0
        self._cache_revision = -1
        self._cache: RobotState | None = None
        self.reset()

    @property
    def gripper(self) -> bool:
        return self._gripper

    @property
    def action_size(self) -> int:
        return action_size(self._gripper)

    def reset(self, finger_width: float = 0.0, ee_position: npt.ArrayLike | None = None) -> None:
        """Put the arm at rest in the neutral pose, or pointing down with its end effector at
        ``ee_position`` (clipped to ``WORKSPACE``); fingers at ``finger_width`` (m).

        Without the gripper the fingers always reset closed.
        """
        width = float(np.clip(finger_width, 0.0, MAX_FINGER_WIDTH)) if self._gripper else 0.0
        self._finger_target = width / 2.0
        positions = self._teleport(NEUTRAL_ARM)
        if ee_position is not None:
            # One IK call moves a few centimetres accurately; from the neutral pose to a far corner takes
            # a handful, each starting where the last one left the arm.
            target = WORKSPACE.clip(ee_position).tolist()
            for _ in range(RESET_IK_ROUNDS):
                positions = self._teleport(self._ik.solve(target, positions).tolist())
        self._command(positions)

    def _teleport(self, arm: Sequence[float]) -> list[float]:
        """Set the arm's joints (fingers at their target) at rest; returns every controlled joint's angle."""
        positions = [*arm, self._finger_target, self._finger_target]
        for joint, angle in zip(CONTROLLED_JOINTS, positions, strict=True):
            self._client.resetJointState(self.body_id, joint, angle, 0.0)
        self._world.invalidate()
        return positions

    def clear_of(self, body_ids: Sequence[int], margin: float) -> bool:
        """Whether every part of the arm is at least ``margin`` (m) away from each body in ``body_ids``."""
        return not any(self._get_closest(bodyA=self.body_id, bodyB=body, distance=margin) for body in body_ids)

    def _command(self, positions: Sequence[float]) -> None:
        self._set_motors(
            self.body_id,
            CONTROLLED_JOINTS,
            pybullet.POSITION_CONTROL,
            targetPositions=positions,
            forces=self._forces,
            positionGains=self._gains,
        )

    def ee_target(self, action: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """End-effector target (m, world frame) that ``action`` asks for from here."""
        move = np.clip(np.asarray(action, dtype=np.float64)[:3], -1.0, 1.0) * MAX_STEP
        return WORKSPACE.clip(self.state().ee_position + move)

    def apply_action(self, action: npt.ArrayLike) -> None:
        """Set joint targets for one control step; the world's ``step`` then moves the arm.

        ``action[:3]`` in [-1, 1] (clipped) moves the end effector by up to ``MAX_STEP``
        per axis, with the target clipped to ``WORKSPACE``; ``action[3]`` (gripper only)
        maps [-1, 1] to finger widths [0, ``MAX_FINGER_WIDTH``].
        """
        values = np.asarray(action, dtype=np.float64).reshape(-1)
        if values.shape[0] != self.action_size:
            raise ValueError(f"expected an action of size {self.action_size}, got {values.shape[0]}")
        if not np.isfinite(values).all():
            raise ValueError(f"action must be finite, got {values}")
        if self._gripper:
            opening = (min(max(float(values[3]), -1.0), 1.0) + 1.0) / 2.0
            self._finger_target = opening * MAX_FINGER_WIDTH / 2.0
        self._move(self.ee_target(values))

    def _move(self, target: npt.NDArray[np.float64]) -> None:
        joints = self.state().joint_positions
        positions = self._ik.solve(target.tolist(), joints.tolist()).tolist()
        positions.append(self._finger_target)
        positions.append(self._finger_target)
        self._command(positions)

    def state(self) -> RobotState:
        """End-effector and joint state, re-read from PyBullet only after the world changed."""
        revision = self._world.revision
        if self._cache is not None and self._cache_revision == revision:
            return self._cache
        link = self._get_link_state(self.body_id, EE_LINK, computeLinkVelocity=1)
        joints = self._get_joint_states(self.body_id, CONTROLLED_JOINTS)
        positions = np.array([joint[0] for joint in joints], dtype=np.float64)
        self._cache = RobotState(
            ee_position=_read_only(np.array(link[4], dtype=np.float64)),
            ee_velocity=_read_only(np.array(link[6], dtype=np.float64)),
            finger_width=float(positions[-2] + positions[-1]),
            joint_positions=_read_only(positions),
        )
        self._cache_revision = revision
        return self._cache

    def contacts(self, body_ids: Sequence[int]) -> Contacts:
        """Which parts of the robot touch each body in ``body_ids`` after the last step."""
        index = {body: i for i, body in enumerate(body_ids)}
        n = len(body_ids)
        left = np.zeros(n, dtype=bool)
        right = np.zeros(n, dtype=bool)
        hand = np.zeros(n, dtype=bool)
        robot = np.zeros(n, dtype=bool)
        for point in self._get_contacts(bodyA=self.body_id):
            i = index.get(point[2])
            if i is None:
                continue
            link = point[3]
            robot[i] = True
            if link >= HAND_LINK:
                hand[i] = True
            if link == LEFT_FINGER_LINK:
                left[i] = True
            elif link == RIGHT_FINGER_LINK:
                right[i] = True
        return Contacts(left_finger=left, right_finger=right, hand=hand, robot=robot)
