"""The observation normaliser: statistics per arm feature and per object feature shared over the slots,
gathered over present objects only, so that where an object sits and how many others share its scene do not
change what the networks see."""

from __future__ import annotations

import io

import numpy as np
import pytest
import torch

from lanrocli.agent.networks import ObjectLayout
from lanrocli.agent.normalizer import RunningNormalizer
from lanrocli.agent.sac import SACAgent
from lanrocli.agent.settings import SACSettings
from tests.agent.episodes import ACTION_DIM, OBS_DIM, VOCAB

LAYOUT = ObjectLayout(arm=3, object=4, slots=3)


def _scenes(rng: np.random.Generator, n: int, slots_filled: float = 0.6) -> np.ndarray:
    """Raw observations whose objects sit in random slots (any subset, none included), the rest zeros as an
    environment pads them. Objects are offset from zero so that empty slots would show in their mean."""
    obs = np.zeros((n, LAYOUT.size))
    obs[:, : LAYOUT.arm] = rng.normal(-1.0, 2.0, size=(n, LAYOUT.arm))
    objects = obs[:, LAYOUT.arm :].reshape(n, LAYOUT.slots, LAYOUT.object)
    filled = rng.random((n, LAYOUT.slots)) < slots_filled
    objects[filled] = rng.normal(3.0, [1.0, 0.5, 4.0, 2.0], size=(int(filled.sum()), LAYOUT.object))
    return obs


def _fitted(seed: int = 0) -> RunningNormalizer:
    norm = RunningNormalizer(LAYOUT, clip=5.0, eps=1e-4)
    norm.update(_scenes(np.random.default_rng(seed), 200))
    return norm


def _permute(obs: torch.Tensor, order: list[int]) -> torch.Tensor:
    arm, objects = LAYOUT.split(obs)
    return torch.cat([arm, objects[:, order].reshape(obs.shape[0], -1)], dim=1)


def test_without_objects_every_feature_has_the_statistics_of_everything_seen() -> None:
    rng = np.random.default_rng(0)
    norm = RunningNormalizer(ObjectLayout(4, 0, 0), clip=5.0, eps=1e-8)
    chunks = [rng.normal(3.0, [1.0, 2.0, 0.5, 10.0], size=(n, 4)) for n in (1, 7, 100, 33)]
    for chunk in chunks:
        norm.update(chunk.astype(np.float32))
    seen = np.concatenate(chunks).astype(np.float32).astype(np.float64)
    np.testing.assert_allclose(norm.mean.numpy(), seen.mean(0), rtol=1e-10)
    np.testing.assert_allclose(norm.var.numpy(), seen.var(0), rtol=1e-9)
    x = torch.as_tensor(seen, dtype=torch.float32)
    expected = ((seen - seen.mean(0)) / np.sqrt(seen.var(0) + 1e-8)).clip(-5, 5)
    np.testing.assert_allclose(norm(x).numpy(), expected, rtol=1e-4, atol=1e-5)
    assert norm(torch.full((1, 4), 1e6)).max() == 5.0


def test_object_statistics_come_from_the_present_objects_only() -> None:
    layout = ObjectLayout(arm=1, object=2, slots=3)
    obs = np.array(
        [
            [1.0, 1.0, 2.0, 3.0, 4.0, 0.0, 0.0],
            [3.0, 0.0, 0.0, 5.0, 6.0, 0.0, 8.0],  # an object with a zero feature is present all the same
            [5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],  # a scene without objects counts for the arm only
        ]
    )
    present = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0], [0.0, 8.0]])
    norm = RunningNormalizer(layout, clip=100.0, eps=0.0)
    norm.update(obs)
    np.testing.assert_allclose(norm.count.numpy(), [3, 4, 4])
    np.testing.assert_allclose(norm.mean.numpy(), [3.0, *present.mean(0)], rtol=1e-12)
    np.testing.assert_allclose(norm.var.numpy(), [8 / 3, *present.var(0)], rtol=1e-12)
    out = norm(torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(out[1, 3:5], (present[2] - present.mean(0)) / present.std(0), rtol=1e-6)


def test_updates_in_batches_merge_to_the_statistics_of_one_update_in_float64() -> None:
    rng = np.random.default_rng(1)
    chunks = [_scenes(rng, n) for n in (1, 7, 100, 33)] + [_scenes(rng, 5, slots_filled=0.0)]
    piecewise = RunningNormalizer(LAYOUT, clip=5.0, eps=1e-4)
    for chunk in chunks:
        piecewise.update(chunk)
    whole = RunningNormalizer(LAYOUT, clip=5.0, eps=1e-4)
    whole.update(np.concatenate(chunks))
    assert piecewise.mean.dtype == piecewise.var.dtype == torch.float64
    for name in ("count", "mean", "var"):
        torch.testing.assert_close(getattr(piecewise, name), getattr(whole, name), rtol=1e-12, atol=0.0)
    seen = np.concatenate(chunks)
    objects = seen[:, LAYOUT.arm :].reshape(-1, LAYOUT.object)
    objects = objects[(objects != 0).any(axis=1)]
    np.testing.assert_allclose(piecewise.mean.numpy(), [*seen[:, : LAYOUT.arm].mean(0), *objects.mean(0)], rtol=1e-12)
    np.testing.assert_allclose(piecewise.var.numpy(), [*seen[:, : LAYOUT.arm].var(0), *objects.var(0)], rtol=1e-12)


def test_permuting_the_slots_permutes_the_normalised_objects() -> None:
    norm = _fitted()
    obs = torch.as_tensor(_scenes(np.random.default_rng(2), 50), dtype=torch.float32)
    out = norm(obs)
    for order in ([1, 0, 2], [2, 1, 0], [1, 2, 0]):
        assert torch.equal(norm(_permute(obs, order)), _permute(out, order))


def test_adding_an_object_leaves_the_arm_and_the_other_objects_as_they_were() -> None:
    norm = _fitted()
    rng = np.random.default_rng(3)
    three = torch.as_tensor(_scenes(rng, 20, slots_filled=1.0), dtype=torch.float32)
    two = three.clone()
    two[:, -LAYOUT.object :] = 0.0
    before, after = norm(two), norm(three)
    assert torch.equal(before[:, : -LAYOUT.object], after[:, : -LAYOUT.object])
    assert (after[:, -LAYOUT.object :] != 0).all()
    # And the added object reads as it would in the first slot.
    assert torch.equal(
        after[:, -LAYOUT.object :], norm(_permute(three, [2, 0, 1]))[:, LAYOUT.arm : LAYOUT.arm + LAYOUT.object]
    )


def test_empty_slots_normalise_to_zero() -> None:
    norm = _fitted()
    assert (norm.mean[LAYOUT.arm :].abs() > 1.0).all(), "objects away from zero, so an empty slot would show"
    obs = torch.as_tensor(_scenes(np.random.default_rng(4), 100), dtype=torch.float32)
    _, objects = LAYOUT.split(norm(obs))
    empty = ~LAYOUT.present(obs)
    assert empty.any() and (objects[empty] == 0).all()
    assert (objects[~empty] != 0).any(dim=1).all()


def _round_trip(state: dict) -> dict:
    file = io.BytesIO()
    torch.save(state, file)
    file.seek(0)
    return torch.load(file, weights_only=True)


def test_state_round_trips_through_a_weights_only_load() -> None:
    norm = _fitted()
    state = _round_trip(norm.state_dict())
    assert RunningNormalizer.saved_layout(state) == LAYOUT
    other = RunningNormalizer(LAYOUT, clip=5.0, eps=1e-4)
    other.load_state_dict(state)
    x = torch.as_tensor(_scenes(np.random.default_rng(5), 10), dtype=torch.float32)
    assert torch.equal(norm(x), other(x))


def test_statistics_of_another_layout_or_kept_per_slot_are_refused_clearly() -> None:
    norm = _fitted()
    other = RunningNormalizer(ObjectLayout(arm=7, object=2, slots=3), clip=5.0, eps=1e-4)
    with pytest.raises(ValueError, match="gathered under the layout"):
        other.load_state_dict(norm.state_dict())
    assert other.count.sum() == 0, "a refused state changes nothing"
    per_slot = {
        "count": torch.tensor(5.0, dtype=torch.float64),
        "mean": torch.zeros(LAYOUT.size, dtype=torch.float64),
        "var": torch.ones(LAYOUT.size, dtype=torch.float64),
    }
    with pytest.raises(ValueError, match="own statistics"):
        norm.load_state_dict(per_slot)
    with pytest.raises(ValueError, match="own statistics"):
        RunningNormalizer.saved_layout(per_slot)


def test_a_flat_agent_shares_the_statistics_too_and_keeps_them_through_its_state() -> None:
    layout = ObjectLayout(arm=2, object=3, slots=2)
    agent = SACAgent(OBS_DIM, ACTION_DIM, len(VOCAB), SACSettings(architecture="flat"), layout=layout)
    obs = np.random.default_rng(6).normal(size=(30, OBS_DIM))
    obs[::2, -layout.object :] = 0.0
    agent.update_normalizer(obs)
    assert agent.normalizer.mean.shape == (layout.arm + layout.object,)
    resumed = SACAgent.from_state_dict(_round_trip(agent.state_dict()))
    x = torch.as_tensor(obs, dtype=torch.float32)
    assert torch.equal(agent.normalizer(x), resumed.normalizer(x))
    assert (agent.normalizer(x)[::2, -layout.object :] == 0).all()
