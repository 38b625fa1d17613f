from __future__ import annotations

import numpy as np
import pytest

from lanrocli.sim import COLOURS, SHAPES, ObjectSet, World, resting_position

EXPECTED_COLOURS = {"red", "green", "blue", "yellow", "purple", "orange", "pink", "cyan", "brown"}


def test_catalogue_has_the_grammar_properties() -> None:
    assert set(COLOURS) == EXPECTED_COLOURS
    assert set(SHAPES) == {"cube", "cuboid", "cylinder"}
    for spec in SHAPES.values():
        assert all(0.015 <= h <= 0.04 for h in spec.half_extents)
    cuboid = SHAPES["cuboid"].half_extents
    assert cuboid[0] > 1.5 * cuboid[1]


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_spawned_object_rests_on_the_table(world: World, objects: ObjectSet, shape: str) -> None:
    obj = objects.spawn(shape, "purple", resting_position(shape, 0.1, -0.05))
    for _ in range(50):
        world.step()
    states = objects.states()
    np.testing.assert_allclose(states.positions[0], [0.1, -0.05, obj.height / 2], atol=0.002)
    np.testing.assert_allclose(np.abs(states.orientations[0]), [0, 0, 0, 1], atol=0.01)
    np.testing.assert_allclose(states.linear_velocities[0], 0.0, atol=0.005)
    np.testing.assert_allclose(states.angular_velocities[0], 0.0, atol=0.05)


@pytest.mark.parametrize("colour", sorted(EXPECTED_COLOURS))
def test_object_has_its_colour_and_size(world: World, objects: ObjectSet, colour: str) -> None:
    obj = objects.spawn("cuboid", colour, resting_position("cuboid", 0.0, 0.0))
    visual = world.client.getVisualShapeData(obj.body_id)[0]
    np.testing.assert_allclose(visual[7], COLOURS[colour], atol=1e-6)
    np.testing.assert_allclose(np.array(visual[3]) / 2, SHAPES["cuboid"].half_extents, atol=1e-6)
    low, high = world.client.getAABB(obj.body_id)
    np.testing.assert_allclose((np.array(high) - np.array(low)) / 2, obj.half_extents, atol=0.003)
    assert (obj.shape, obj.colour) == ("cuboid", colour)


def test_unknown_properties_are_rejected(objects: ObjectSet) -> None:
    with pytest.raises(ValueError):
        objects.spawn("sphere", "red", [0.0, 0.0, 0.1])
    with pytest.raises(ValueError):
        objects.spawn("cube", "azure", [0.0, 0.0, 0.1])


def test_states_cover_all_objects_in_spawn_order(world: World, objects: ObjectSet) -> None:
    placements = [("cube", 0.1, 0.1), ("cylinder", -0.1, 0.0), ("cuboid", 0.0, -0.1)]
    for shape, x, y in placements:
        objects.spawn(shape, "red", resting_position(shape, x, y))
    world.step()
    states = objects.states()
    assert states.positions.shape == (3, 3)
    assert states.orientations.shape == (3, 4)
    assert states.linear_velocities.shape == (3, 3)
    assert states.angular_velocities.shape == (3, 3)
    np.testing.assert_allclose(states.positions[:, :2], [p[1:] for p in placements], atol=0.002)
    assert objects.states() is states
    with pytest.raises(ValueError):
        states.positions[0, 0] = 1.0


def test_clear_and_respawn_reuses_shapes(world: World, objects: ObjectSet) -> None:
    bodies = world.client.getNumBodies()
    for episode in range(5):
        objects.clear()
        objects.spawn("cube", "red", resting_position("cube", 0.05 * episode - 0.1, 0.0))
        objects.spawn("cylinder", "green", resting_position("cylinder", 0.0, 0.1))
        assert world.client.getNumBodies() == bodies + 2
        assert len(objects) == 2
    for _ in range(25):
        world.step()
    positions = objects.states().positions
    np.testing.assert_allclose(positions[:, 2], [0.025, 0.025], atol=0.002)
    objects.clear()
    assert world.client.getNumBodies() == bodies
    assert objects.states().positions.shape == (0, 3)


def test_reset_poses_teleports_and_stops_objects(world: World, objects: ObjectSet) -> None:
    objects.spawn("cube", "red", [0.0, 0.0, 0.3])
    objects.spawn("cuboid", "blue", [0.1, 0.0, 0.3])
    for _ in range(3):
        world.step()
    assert objects.states().linear_velocities[0, 2] < -0.5
    quarter_turn = [0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)]
    targets = [resting_position("cube", -0.1, 0.1), resting_position("cuboid", 0.1, -0.1)]
    objects.reset_poses(targets, [[0, 0, 0, 1], quarter_turn])
    states = objects.states()
    np.testing.assert_allclose(states.positions, targets, atol=1e-9)
    np.testing.assert_allclose(states.orientations[1], quarter_turn, atol=1e-9)
    np.testing.assert_allclose(states.linear_velocities, 0.0, atol=1e-12)
    np.testing.assert_allclose(states.angular_velocities, 0.0, atol=1e-12)
