from __future__ import annotations

import numpy as np
import pytest

from lanrocli.sim import CONTROL_DT, ObjectSet, Panda, World, resting_position


def test_two_worlds_do_not_see_each_other() -> None:
    first, second = World(), World()
    try:
        bodies_in_second = second.client.getNumBodies()
        below = ObjectSet(first)
        below.spawn("cube", "red", resting_position("cube", 0.0, 0.0))
        above = ObjectSet(second)
        above.spawn("cube", "blue", [0.0, 0.0, 0.2])
        assert second.client.getNumBodies() == bodies_in_second + 1
        for _ in range(15):
            first.step()
            second.step()
        # The falling cube lands on its own table, not on the other world's cube.
        assert above.states().positions[0, 2] == pytest.approx(0.025, abs=0.002)
        assert below.states().positions[0, 2] == pytest.approx(0.025, abs=0.002)
    finally:
        first.close()
        second.close()


def test_robots_in_two_worlds_move_independently() -> None:
    first, second = World(), World()
    try:
        a, b = Panda(first), Panda(second)
        for _ in range(5):
            a.apply_action([1.0, 0.0, 0.0])
            b.apply_action([0.0, 0.0, 0.0])
            first.step()
            second.step()
        assert a.state().ee_position[0] > 0.1
        assert abs(b.state().ee_position[0]) < 0.005
    finally:
        first.close()
        second.close()


def test_step_advances_time_by_control_dt(world: World) -> None:
    assert pytest.approx(0.04) == CONTROL_DT
    assert world.time == 0.0
    for _ in range(3):
        world.step()
    assert world.steps == 3
    assert world.time == pytest.approx(0.12)


def test_one_step_is_forty_milliseconds_of_free_fall(world: World) -> None:
    objects = ObjectSet(world)
    objects.spawn("cube", "red", [0.0, 0.0, 1.0])
    world.client.changeDynamics(objects[0].body_id, -1, linearDamping=0.0)
    world.step()
    assert objects.states().linear_velocities[0, 2] == pytest.approx(-9.81 * 0.04, rel=1e-6)


def test_step_physics_moves_bodies_without_advancing_the_clock(world: World) -> None:
    objects = ObjectSet(world)
    objects.spawn("cube", "red", [0.0, 0.0, 1.0])
    revision = world.revision
    world.step_physics()
    assert world.time == 0.0 and world.revision == revision
    position, _ = world.client.getBasePositionAndOrientation(objects[0].body_id)
    assert position[2] < 1.0


def test_render_returns_rgb_uint8(world: World) -> None:
    Panda(world)
    ObjectSet(world).spawn("cube", "red", resting_position("cube", 0.0, 0.0))
    image = world.render(64, 48)
    assert image.shape == (48, 64, 3)
    assert image.dtype == np.uint8
    assert image.std() > 5.0


def test_render_rejects_empty_images(world: World) -> None:
    with pytest.raises(ValueError):
        world.render(0, 10)


def test_close_twice_is_harmless() -> None:
    w = World()
    w.close()
    w.close()


@pytest.mark.parametrize("images", [True, False])
def test_same_actions_give_same_states_drawn_or_not(images: bool) -> None:
    """A world that will never be drawn leaves the arm's visual meshes out; its physics must not change."""

    def rollout(images: bool = True) -> np.ndarray:
        with World(images=images) as w:
            robot = Panda(w, gripper=True)
            objects = ObjectSet(w)
            objects.spawn("cube", "red", resting_position("cube", 0.05, 0.0))
            objects.spawn("cylinder", "blue", resting_position("cylinder", -0.05, 0.05))
            actions = np.random.default_rng(3).uniform(-1.0, 1.0, size=(40, 4))
            trace = []
            for action in actions:
                robot.apply_action(action)
                w.step()
                states = [np.ravel(a) for a in objects.states()]
                trace.append(np.concatenate([robot.state().ee_position, *states]))
            return np.array(trace)

    np.testing.assert_array_equal(rollout(images), rollout())


def test_a_world_built_without_images_has_no_arm_meshes_and_refuses_to_draw() -> None:
    with World(images=False) as undrawn, World() as drawn:
        # Without its visual meshes PyBullet shows the arm's collision meshes in their place.
        meshes = [{shape[4] for shape in w.client.getVisualShapeData(Panda(w).body_id)} for w in (undrawn, drawn)]
        assert not any(b"/visual/" in mesh for mesh in meshes[0])
        assert any(b"/visual/" in mesh for mesh in meshes[1])
        with pytest.raises(RuntimeError, match="images=True"):
            undrawn.render(8, 8)
    with pytest.raises(ValueError, match="images=True"):
        World(gui=True, images=False)
