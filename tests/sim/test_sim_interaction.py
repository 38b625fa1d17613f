"""Contacts, pushing and a scripted grasp-and-lift, as the tasks and the oracle need them."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from lanrocli.sim import ObjectSet, Panda, World, resting_position


def test_no_contact_without_touching(
    world: World, panda: Panda, objects: ObjectSet, drive_to: Callable[..., int]
) -> None:
    objects.spawn("cube", "red", resting_position("cube", 0.0, 0.1))
    drive_to(world, panda, [0.0, 0.04, 0.025])
    contacts = panda.contacts(objects.body_ids)
    assert not contacts.robot.any()
    assert not contacts.left_finger.any() and not contacts.right_finger.any()


def test_finger_pressed_slowly_against_an_object_touches_it(
    world: World, panda: Panda, objects: ObjectSet, drive_to: Callable[..., int]
) -> None:
    # Fast pushes kick the object ahead of the finger, so contact is checked while pushing
    # at 2 mm per step, where the finger stays on the object.
    objects.spawn("cube", "green", resting_position("cube", 0.1, -0.1))
    objects.spawn("cube", "red", resting_position("cube", 0.0, 0.1))
    drive_to(world, panda, [0.0, 0.03, 0.025])
    for _ in range(12):
        panda.apply_action([0.0, 0.05, 0.0])
        world.step()
    contacts = panda.contacts(objects.body_ids)
    assert contacts.right_finger.tolist() == [False, True]
    assert contacts.left_finger.tolist() == [False, False]
    assert contacts.hand.tolist() == [False, True]
    assert contacts.robot.tolist() == [False, True]
    assert objects.states().positions[1, 1] > 0.101


def test_left_finger_is_on_the_minus_y_side(
    world: World, panda: Panda, objects: ObjectSet, drive_to: Callable[..., int]
) -> None:
    objects.spawn("cube", "red", resting_position("cube", 0.0, -0.1))
    drive_to(world, panda, [0.0, -0.03, 0.025])
    for _ in range(12):
        panda.apply_action([0.0, -0.05, 0.0])
        world.step()
    contacts = panda.contacts(objects.body_ids)
    assert contacts.left_finger[0] and not contacts.right_finger[0]


def test_pushing_forward_slides_the_object(
    world: World, panda: Panda, objects: ObjectSet, drive_to: Callable[..., int]
) -> None:
    objects.spawn("cube", "blue", resting_position("cube", 0.0, 0.0))
    drive_to(world, panda, [-0.07, 0.0, 0.1])
    drive_to(world, panda, [-0.07, 0.0, 0.02])
    drive_to(world, panda, [0.08, 0.0, 0.02], max_steps=12)
    state = objects.states()
    assert state.positions[0, 0] > 0.08
    assert abs(state.positions[0, 1]) < 0.02
    assert state.positions[0, 2] == pytest.approx(0.025, abs=0.003)


@pytest.mark.parametrize(
    ("shape", "x", "y", "yaw"),
    [("cube", 0.1, 0.05, 0.3), ("cuboid", -0.12, -0.1, 0.0), ("cylinder", 0.0, 0.14, 0.0)],
)
def test_scripted_grasp_and_lift(
    world: World,
    gripper_panda: Panda,
    objects: ObjectSet,
    drive_to: Callable[..., int],
    hold_still: Callable[..., None],
    shape: str,
    x: float,
    y: float,
    yaw: float,
) -> None:
    orientation = [0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)]
    obj = objects.spawn(shape, "orange", resting_position(shape, x, y), orientation)
    centre = objects.states().positions[0].copy()
    drive_to(world, gripper_panda, centre + [0.0, 0.0, 0.1], grip=1.0)
    drive_to(world, gripper_panda, centre, grip=1.0)
    hold_still(world, gripper_panda, 5, grip=-1.0)
    contacts = gripper_panda.contacts(objects.body_ids)
    assert contacts.left_finger[0] and contacts.right_finger[0]
    assert gripper_panda.state().finger_width == pytest.approx(2 * obj.half_extents[1], abs=0.01)
    drive_to(world, gripper_panda, [x, y, 0.2], grip=-1.0)
    hold_still(world, gripper_panda, 10, grip=-1.0)
    lifted = objects.states().positions[0]
    assert lifted[2] > 0.17
    np.testing.assert_allclose(lifted[:2], [x, y], atol=0.02)
    drive_to(world, gripper_panda, [x, y, centre[2] + 0.02], grip=-1.0)
    hold_still(world, gripper_panda, 15, grip=1.0)
    assert objects.states().positions[0, 2] == pytest.approx(obj.height / 2, abs=0.005)
