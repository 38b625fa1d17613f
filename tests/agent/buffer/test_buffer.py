"""The replay buffer: whole episodes only, relabelling by the stored facts, an exact state to save and load."""

from __future__ import annotations

import json
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lanrocli.agent.buffer.replay_buffer import ReplayBuffer
from lanrocli.agent.buffer.transitions import Batch, EpisodeData
from lanrocli.agent.settings import BufferSettings
from lanrocli.core.choices import CorrectionForm
from tests.agent.episodes import ACTION_DIM, OBS_DIM, VOCAB, random_episode
from tests.agent.sentences import parse, referents


def _filled(
    capacity: int, episodes: int, seed: int = 0, edit: Callable[[int, EpisodeData], None] | None = None
) -> tuple[ReplayBuffer, dict[int, EpisodeData]]:
    """A buffer of random episodes; ``edit(i, episode)`` may change each before it is added."""
    rng = np.random.default_rng(seed)
    buffer = ReplayBuffer(capacity, OBS_DIM, ACTION_DIM, max_objects=3, seed=seed)
    added = {}
    for i in range(episodes):
        episode = random_episode(rng, i)
        if edit is not None:
            edit(i, episode)
        buffer.add_episode(episode)
        added[i] = episode
    return buffer, added


def _drawn(**changes: object) -> BufferSettings:
    """Sampling settings that draw uniformly and relabel nothing, with ``changes``."""
    return BufferSettings(**{"relabel_ratio": 0.0, "correction_share": 0.0, "hindsight_share": 0.0, **changes})


def _origin(batch: Batch, row: int, added: dict[int, EpisodeData]) -> tuple[EpisodeData, int]:
    """The episode and step a sampled transition came from, read from the marks in its observation."""
    return added[int(batch.obs[row, 0])], int(batch.obs[row, 1])


def test_samples_come_only_from_episodes_that_are_still_whole() -> None:
    buffer, added = _filled(capacity=200, episodes=120)  # wraps around many times
    stored_obs = buffer.data["obs"]
    rng = np.random.default_rng(1)
    sampled: set[int] = set()
    for _ in range(200):
        batch = buffer.sample(64, rng, _drawn())
        for row, slot in enumerate(batch.slots):
            episode, step = _origin(batch, row, added)
            start = slot - step
            whole = stored_obs[start : start + len(episode)]
            assert np.array_equal(whole, episode.observations), "sampled an episode that was partly overwritten"
            assert batch.next_obs[row, 1] == step + 1 and batch.next_obs[row, 0] == batch.obs[row, 0]
            sampled.add(int(batch.obs[row, 0]))
    # The most recent episodes that fit in the ring beside the space lost to wrapping are all available.
    recent, total = set(), 0
    for i in reversed(range(len(added))):
        total += len(added[i])
        if total > 200 - 2 * 30:
            break
        recent.add(i)
    assert recent <= sampled
    assert len(buffer) == sum(len(added[i]) for i in sampled)


def test_relabelled_sentences_name_a_future_achievement_and_rewards_follow_eq_1() -> None:
    buffer, added = _filled(capacity=5000, episodes=200)
    rng = np.random.default_rng(2)
    relabelled = 0
    for _ in range(40):
        batch = buffer.sample(256, rng, _drawn(relabel_ratio=1.0, correction_share=0.5))
        for row in range(256):
            episode, step = _origin(batch, row, added)
            objects = list(episode.objects)
            identifiable = [objects.count(o) == 1 for o in objects]
            future = episode.achieved[step:] & np.array(identifiable)
            if not batch.relabelled[row]:
                assert not future.any(), "ratio 1 relabels every transition that can be"
                assert np.array_equal(batch.instruction[row], episode.instructions[step])
                assert np.array_equal(batch.next_instruction[row], episode.next_instructions[step])
                assert batch.reward[row] == episode.rewards[step] and batch.done[row] == episode.terminated[step]
                assert batch.named[row] == -1
                continue
            relabelled += 1
            assert np.array_equal(batch.instruction[row], batch.next_instruction[row])
            (k,) = referents(parse(VOCAB.decode(batch.instruction[row]), episode.task), objects)
            assert future[:, k].any(), "the named object is achieved at this step or later"
            assert batch.named[row] == k
            achieved_now = bool(episode.achieved[step, k])
            assert batch.reward[row] == (0.0 if achieved_now else -1.0)
            assert batch.done[row] == achieved_now
    assert relabelled > 1000


def test_correction_share_sets_the_style_of_relabelled_sentences() -> None:
    buffer, added = _filled(capacity=5000, episodes=200)
    rng = np.random.default_rng(3)
    for share, expect_corrections in ((0.0, False), (1.0, True)):
        batch = buffer.sample(512, rng, _drawn(relabel_ratio=1.0, correction_share=share))
        for row in np.flatnonzero(batch.relabelled):
            episode, _ = _origin(batch, row, added)
            parsed = parse(VOCAB.decode(batch.instruction[row]), episode.task)
            # A scene of one object has nothing to correct: its relabelled sentences stay plain.
            assert (parsed.beginning is not None) == (expect_corrections and len(episode.objects) > 1)


def test_fresh_targets_are_never_achieved_before_the_step() -> None:
    buffer, added = _filled(capacity=5000, episodes=200, seed=4)
    rng = np.random.default_rng(4)
    stale = {False: 0, True: 0}
    for fresh in (False, True):
        for _ in range(20):
            batch = buffer.sample(256, rng, _drawn(relabel_ratio=1.0, fresh_targets=fresh))
            for row in np.flatnonzero(batch.relabelled):
                episode, step = _origin(batch, row, added)
                stale[fresh] += bool(step > 0 and episode.achieved[step - 1, batch.named[row]])
    assert stale[False] > 100 and stale[True] == 0


def test_corrected_relabels_negate_the_object_the_arm_acted_on_first() -> None:
    rng = np.random.default_rng(5)
    buffer = ReplayBuffer(5000, OBS_DIM, ACTION_DIM, max_objects=3, seed=5)
    added = {}
    for i in range(300):
        added[i] = random_episode(rng, i)
        buffer.add_episode(added[i])
    negations = 0
    for _ in range(20):
        batch = buffer.sample(256, rng, _drawn(relabel_ratio=1.0, correction_share=1.0))
        for row in np.flatnonzero(batch.relabelled):
            episode, _ = _origin(batch, row, added)
            parsed = parse(VOCAB.decode(batch.instruction[row]), episode.task)
            first = np.where(episode.achieved.any(axis=0), np.argmax(episode.achieved, axis=0), len(episode))
            first[batch.named[row]] = len(episode) + 1
            if parsed.beginning is CorrectionForm.NEGATION and first.min() < len(episode):
                negations += 1
                assert parsed.corrected.fits(episode.objects[int(np.argmin(first))])
    assert negations > 50


def test_ground_real_labels_goals_only_where_the_sentence_names_them() -> None:
    def correct_halfway(i: int, episode: EpisodeData) -> None:
        if i % 2 and len(episode) > 2:  # a correction episode whose correction is spoken halfway
            episode.correction_episode = True
            half = len(episode) // 2
            episode.instructions[half:] = VOCAB.encode(VOCAB.decode(episode.instructions[0]) + " sorry the red cube")
            episode.next_instructions[half - 1 :] = episode.instructions[half]

    buffer, added = _filled(5000, 200, seed=6, edit=correct_halfway)
    rng = np.random.default_rng(6)
    labelled = pending = 0
    for ground in (False, True):
        batch = buffer.sample(1024, rng, _drawn(relabel_ratio=0.5, ground_real=ground))
        assert np.array_equal(batch.label[batch.relabelled], batch.named[batch.relabelled])
        for row in np.flatnonzero(~batch.relabelled):
            episode, step = _origin(batch, row, added)
            still_pending = episode.correction_episode and step < len(episode) // 2
            pending += still_pending
            expected = episode.goal_index if ground and not still_pending else -1
            assert batch.label[row] == expected
            labelled += batch.label[row] >= 0
    assert labelled > 100 and pending > 20


def test_hindsight_share_draws_that_share_from_transitions_relabelling_can_use() -> None:
    buffer, added = _filled(capacity=20000, episodes=400, seed=8)
    relabelable = buffer.data["valid"] & (buffer.data["future_count"] > 0)
    natural = relabelable[: buffer.high].sum() / len(buffer)
    rng = np.random.default_rng(9)
    for share in (0.0, 0.5, 1.0):
        batch = buffer.sample(4096, rng, _drawn(hindsight_share=share))
        drawn = relabelable[batch.slots].mean()
        expected = share + (1.0 - share) * natural
        assert abs(drawn - expected) < 0.03, (share, drawn, expected)
        for row in range(0, 4096, 97):  # whole episodes still: every slot still maps to its own episode
            episode, step = _origin(batch, row, added)
            assert np.array_equal(batch.obs[row], episode.observations[step])
    assert natural < 0.9  # the share is what moves the rate, not episodes that all achieve something


def test_no_relabelling_at_ratio_zero() -> None:
    buffer, _ = _filled(capacity=3000, episodes=100)
    batch = buffer.sample(512, np.random.default_rng(0), _drawn(relabel_ratio=0.0))
    assert not batch.relabelled.any()
    assert np.array_equal(batch.instruction, buffer.data["instruction"][batch.slots])


def test_relabelling_never_changes_what_is_stored() -> None:
    buffer, _ = _filled(capacity=3000, episodes=100)
    before = {name: array.copy() for name, array in buffer.data.items()}
    rng = np.random.default_rng(4)
    for _ in range(30):
        batch = buffer.sample(256, rng, _drawn(relabel_ratio=0.8, correction_share=0.5))
        for array in (batch.obs, batch.instruction, batch.next_instruction, batch.reward, batch.done, batch.action):
            array[...] = 0  # a caller scribbling on its batch must not reach the buffer either
    for name, array in buffer.data.items():
        assert np.array_equal(array, before[name]), name


def test_state_round_trips_exactly_after_wrapping() -> None:
    buffer, _ = _filled(capacity=300, episodes=80, seed=5)
    assert buffer.position < buffer.high  # it has wrapped
    meta, arrays = buffer.state()
    # Plain data: the metadata survives JSON, and the arrays are copied out of the buffer's own.
    loaded = ReplayBuffer.from_state(json.loads(json.dumps(meta)), {k: v.copy() for k, v in arrays.items()})
    assert (loaded.capacity, loaded.position, loaded.high, len(loaded)) == (
        buffer.capacity,
        buffer.position,
        buffer.high,
        len(buffer),
    )
    for name, array in buffer.data.items():
        assert array.dtype == loaded.data[name].dtype
        assert np.array_equal(array, loaded.data[name]), name
    # Both continue identically: same sentence draws when adding, same samples.
    rng = np.random.default_rng(9)
    episode = random_episode(rng, 999)
    buffer.add_episode(episode)
    loaded.add_episode(episode)
    a = buffer.sample(128, np.random.default_rng(1), _drawn(relabel_ratio=0.8, correction_share=0.5))
    b = loaded.sample(128, np.random.default_rng(1), _drawn(relabel_ratio=0.8, correction_share=0.5))
    for field in ("obs", "instruction", "next_instruction", "reward", "done", "relabelled", "named", "slots"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field


def test_sampling_is_reproducible_from_the_generator() -> None:
    buffer, _ = _filled(capacity=2000, episodes=60)
    a = buffer.sample(64, np.random.default_rng(7), _drawn(relabel_ratio=0.8, correction_share=0.5))
    b = buffer.sample(64, np.random.default_rng(7), _drawn(relabel_ratio=0.8, correction_share=0.5))
    assert np.array_equal(a.slots, b.slots) and np.array_equal(a.instruction, b.instruction)


def test_rejects_episodes_that_do_not_fit() -> None:
    rng = np.random.default_rng(0)
    buffer = ReplayBuffer(10, OBS_DIM, ACTION_DIM, seed=0)
    with pytest.raises(ValueError, match="does not fit"):
        buffer.add_episode(random_episode(rng, 0, steps=11))
    episode = random_episode(rng, 1, max_steps=5)
    episode.actions = episode.actions[:, :2]
    with pytest.raises(ValueError, match="actions"):
        buffer.add_episode(episode)
    with pytest.raises(ValueError, match="empty"):
        buffer.sample(4, rng, _drawn())


def test_a_million_transitions_of_a_three_object_scene_fit_in_well_under_a_gigabyte() -> None:
    buffer = ReplayBuffer(1_000_000, 60, 4, max_objects=3)
    assert buffer.bytes_per_transition * 1_000_000 < 0.7e9


@settings(max_examples=60, deadline=None)
@given(capacity=st.integers(5, 60), lengths=st.lists(st.integers(1, 60), min_size=1, max_size=25))
def test_ring_keeps_whole_episodes_only(capacity: int, lengths: list[int]) -> None:
    rng = np.random.default_rng(0)
    buffer = ReplayBuffer(capacity, OBS_DIM, ACTION_DIM, seed=0)
    added = []
    for i, length in enumerate(min(n, capacity) for n in lengths):
        episode = random_episode(rng, i, steps=length)
        buffer.add_episode(episode)
        added.append(episode)
        valid = buffer.data["valid"]
        assert len(buffer) == int(valid.sum())
        stored = buffer.data["obs"]
        for slot in np.flatnonzero(valid):
            episode_id, step = int(stored[slot, 0]), int(stored[slot, 1])
            start = slot - step
            assert np.array_equal(stored[start : start + len(added[episode_id])], added[episode_id].observations)
            assert valid[start : start + len(added[episode_id])].all()
        newest = np.flatnonzero(valid & (stored[:, 0] == i))
        assert newest.size == len(episode), "the episode just added is whole and sampleable"
