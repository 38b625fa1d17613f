"""Scene sampling keeps the paper's overlap rule and the spacing rule on thousands of scenes."""

from __future__ import annotations

import numpy as np
import pytest

from lanrocli.core.choices import Mode
from lanrocli.envs.scene import mode_catalogue, sample_objects, sample_positions


@pytest.mark.parametrize("mode", list(Mode))
@pytest.mark.parametrize("n_objects", [2, 3])
def test_overlap_rule_holds_on_thousands_of_scenes(mode: Mode, n_objects: int) -> None:
    rng = np.random.default_rng(0)
    catalogue = set(mode_catalogue(mode))
    goal_slots = set()
    for i in range(3000):
        objects, goal_index = sample_objects(rng, mode, n_objects, need_shared=i % 2 == 0)
        goal = objects[goal_index]
        assert len(set(objects)) == n_objects and set(objects) <= catalogue
        assert all(o.shared_properties(goal) <= 1 for j, o in enumerate(objects) if j != goal_index)
        if i % 2 == 0:
            assert any(o.shared_properties(goal) == 1 for j, o in enumerate(objects) if j != goal_index)
        goal_slots.add(goal_index)
    assert goal_slots == set(range(n_objects))


def test_mode_catalogues() -> None:
    assert len(mode_catalogue(Mode.COLOUR)) == 9 and {o.shape for o in mode_catalogue(Mode.COLOUR)} == {"cube"}
    assert len(mode_catalogue(Mode.SHAPE)) == 9 and len({o.colour for o in mode_catalogue(Mode.SHAPE)}) == 3
    assert len(mode_catalogue(Mode.COLOUR_SHAPE)) == 27


def test_positions_keep_their_distance_and_area() -> None:
    rng = np.random.default_rng(1)
    low, high = np.array([-0.15, -0.15]), np.array([0.15, 0.15])
    for _ in range(2000):
        p = sample_positions(rng, 3, low, high, 0.15)
        assert np.all(p >= low) and np.all(p <= high)
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)[np.triu_indices(3, 1)]
        assert d.min() >= 0.15


def test_impossible_spacing_is_reported() -> None:
    with pytest.raises(RuntimeError, match="could not place"):
        sample_positions(np.random.default_rng(0), 3, np.zeros(2), np.full(2, 0.05), 0.5, max_tries=20)


@pytest.mark.parametrize("mode", list(Mode))
@pytest.mark.parametrize("n_objects", [2, 3])
def test_same_shape_request_puts_another_object_of_the_goals_shape_on_the_table(mode: Mode, n_objects: int) -> None:
    rng = np.random.default_rng(0)
    for _ in range(3000):
        objects, goal_index = sample_objects(rng, mode, n_objects, need_same_shape=True)
        goal = objects[goal_index]
        others = [o for j, o in enumerate(objects) if j != goal_index]
        assert len(set(objects)) == n_objects and all(o.shared_properties(goal) <= 1 for o in others)
        assert any(o.shape == goal.shape for o in others)


def test_scene_requests_keep_scenes_a_function_of_the_seed() -> None:
    for need in ({"need_shared": True}, {"need_same_shape": True}, {}):
        first = [sample_objects(np.random.default_rng(s), Mode.COLOUR_SHAPE, 3, **need) for s in range(200)]
        again = [sample_objects(np.random.default_rng(s), Mode.COLOUR_SHAPE, 3, **need) for s in range(200)]
        assert first == again
