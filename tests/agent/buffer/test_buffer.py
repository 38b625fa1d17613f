"""The replay buffer: whole episodes only, relabelling by the stored facts, an exact state to save and load."""

from __future__ import annotations

import json
from dataclasses import replace
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lanrocli.agent.buffer.replay_buffer import ReplayBuffer
from lanrocli.agent.buffer.transitions import Batch, EpisodeData
from lanrocli.core.choices import CorrectionForm
from lanrocli.language import grammar_vocabulary

from tests.agent.episodes import ACTION_DIM, OBS_DIM, VOCAB, random_episode
from tests.agent.sentences import chain_referents, parse, referents, split_chain


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


def _origin(batch: Batch, row: int, added: dict[int, EpisodeData]) -> tuple[EpisodeData, int]:
    """The episode and step a sampled transition came from, read from the marks in its observation."""
    return added[int(batch.obs[row, 0])], int(batch.obs[row, 1])


def test_samples_come_only_from_episodes_that_are_still_whole() -> None:
    buffer, added = _filled(capacity=200, episodes=120)  # wraps around many times
    stored_obs = buffer.data["obs"]
    rng = np.random.default_rng(1)
    sampled: set[int] = set()
    for _ in range(200):
        batch = buffer.sample(64, rng)
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
        batch = buffer.sample(256, rng, relabel_ratio=1.0, correction_share=0.5)
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
        batch = buffer.sample(512, rng, relabel_ratio=1.0, correction_share=share)
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
            batch = buffer.sample(256, rng, relabel_ratio=1.0, fresh_targets=fresh)
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
        batch = buffer.sample(256, rng, relabel_ratio=1.0, correction_share=1.0)
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
        batch = buffer.sample(1024, rng, relabel_ratio=0.5, ground_real=ground)
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
        batch = buffer.sample(4096, rng, hindsight_share=share)
        drawn = relabelable[batch.slots].mean()
        expected = share + (1.0 - share) * natural
        assert abs(drawn - expected) < 0.03, (share, drawn, expected)
        for row in range(0, 4096, 97):  # whole episodes still: every slot still maps to its own episode
            episode, step = _origin(batch, row, added)
            assert np.array_equal(batch.obs[row], episode.observations[step])
    assert natural < 0.9  # the share is what moves the rate, not episodes that all achieve something


def test_no_relabelling_at_ratio_zero() -> None:
    buffer, _ = _filled(capacity=3000, episodes=100)
    batch = buffer.sample(512, np.random.default_rng(0), relabel_ratio=0.0)
    assert not batch.relabelled.any()
    assert np.array_equal(batch.instruction, buffer.data["instruction"][batch.slots])


def test_relabelling_never_changes_what_is_stored() -> None:
    buffer, _ = _filled(capacity=3000, episodes=100)
    before = {name: array.copy() for name, array in buffer.data.items()}
    rng = np.random.default_rng(4)
    for _ in range(30):
        batch = buffer.sample(256, rng, relabel_ratio=0.8, correction_share=0.5)
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
        buffer.capacity, buffer.position, buffer.high, len(buffer)
    )
    for name, array in buffer.data.items():
        assert array.dtype == loaded.data[name].dtype
        assert np.array_equal(array, loaded.data[name]), name
    # Both continue identically: same sentence draws when adding, same samples.
    rng = np.random.default_rng(9)
    episode = random_episode(rng, 999)
    buffer.add_episode(episode)
    loaded.add_episode(episode)
    a = buffer.sample(128, np.random.default_rng(1), relabel_ratio=0.8, correction_share=0.5)
    b = loaded.sample(128, np.random.default_rng(1), relabel_ratio=0.8, correction_share=0.5)
    for field in ("obs", "instruction", "next_instruction", "reward", "done", "relabelled", "named", "slots"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field


def test_sampling_is_reproducible_from_the_generator() -> None:
    buffer, _ = _filled(capacity=2000, episodes=60)
    a = buffer.sample(64, np.random.default_rng(7), relabel_ratio=0.8, correction_share=0.5)
    b = buffer.sample(64, np.random.default_rng(7), relabel_ratio=0.8, correction_share=0.5)
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
        buffer.sample(4, rng)


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



def _hand_episode(goal_achieved: bool) -> EpisodeData:
    """Six steps among a red and a blue cube; the goal is the red one (achieved at the last step or never),
    the blue one is achieved from step 2 on. Observations carry (0, step)."""
    from lanrocli.language import ObjectProps

    steps = 6
    achieved = np.zeros((steps, 2), dtype=bool)
    achieved[2:, 1] = True
    achieved[5, 0] = goal_achieved
    obs = np.zeros((steps + 1, OBS_DIM), dtype=np.float32)
    obs[:, 1] = np.arange(steps + 1)
    sentence = np.tile(VOCAB.encode("push the red cube"), (steps, 1))
    return EpisodeData(
        observations=obs[:-1],
        next_observations=obs[1:],
        instructions=sentence,
        next_instructions=sentence.copy(),
        actions=np.zeros((steps, ACTION_DIM), dtype=np.float32),
        rewards=np.where(achieved[:, 0], 0.0, -1.0).astype(np.float32),
        terminated=achieved[:, 0].copy(),
        achieved=achieved,
        goal_index=0,
        objects=(ObjectProps("red", "cube"), ObjectProps("blue", "cube")),
        task="push",
    )


@pytest.mark.parametrize(
    ("goal_achieved", "relabel_ratio", "expected"),
    [
        # step: (return, steps spanned, done), with gamma 0.9 and n 3, worked out by hand
        (True, 0.0, {0: (-2.71, 3, False), 3: (-1.9, 3, True), 4: (-1.0, 2, True), 5: (0.0, 1, True)}),
        (False, 0.0, {0: (-2.71, 3, False), 3: (-2.71, 3, False), 4: (-1.9, 2, False), 5: (-1.0, 1, False)}),
        # relabelled to the blue cube, achieved from step 2 on: the window stops there, done
        (False, 1.0, {0: (-1.9, 3, True), 1: (-1.0, 2, True), 2: (0.0, 1, True), 5: (0.0, 1, True)}),
    ],
)
def test_n_step_returns_match_a_hand_computation(
    goal_achieved: bool, relabel_ratio: float, expected: dict[int, tuple[float, int, bool]]
) -> None:
    buffer = ReplayBuffer(100, OBS_DIM, ACTION_DIM, max_objects=3, seed=0)
    buffer.add_episode(_hand_episode(goal_achieved))
    batch = buffer.sample(400, np.random.default_rng(0), relabel_ratio=relabel_ratio, n_step=3, gamma=0.9)
    seen = set()
    for row in range(400):
        step = int(batch.obs[row, 1])
        if relabel_ratio == 1.0 and step < 5:
            assert batch.named[row] == 1
        if step not in expected:
            continue
        seen.add(step)
        ret, steps, done = expected[step]
        assert batch.reward[row] == pytest.approx(ret, abs=1e-6), step
        assert (int(batch.steps[row]), bool(batch.done[row])) == (steps, done), step
        assert batch.next_obs[row, 1] == step + steps, "the bootstrap reads the state after the last step spanned"
    assert seen == set(expected)


def _n_step_by_loop(
    episode: EpisodeData, step: int, named: int, n: int, gamma: float
) -> tuple[float, int, bool, np.ndarray]:
    """The n-step transition from ``step``, written out one step at a time."""
    ret, k = 0.0, 0
    for t in range(step, min(step + n, len(episode))):
        success = bool(episode.achieved[t, named]) if named >= 0 else bool(episode.terminated[t])
        reward = (0.0 if success else -1.0) if named >= 0 else float(episode.rewards[t])
        ret += gamma**k * reward
        k += 1
        if success:
            return ret, k, True, episode.next_observations[t]
    return ret, k, False, episode.next_observations[step + k - 1]


@pytest.mark.parametrize("n_step", [1, 2, 5])
def test_n_step_sampling_agrees_with_a_step_by_step_loop(n_step: int) -> None:
    buffer, added = _filled(capacity=3000, episodes=150, seed=11)
    rng = np.random.default_rng(12)
    for _ in range(5):
        batch = buffer.sample(256, rng, relabel_ratio=0.8, correction_share=0.5, n_step=n_step, gamma=0.98)
        for row in range(256):
            episode, step = _origin(batch, row, added)
            ret, k, done, next_obs = _n_step_by_loop(episode, step, int(batch.named[row]), n_step, 0.98)
            assert batch.reward[row] == pytest.approx(ret, abs=1e-5)
            assert (int(batch.steps[row]), bool(batch.done[row])) == (k, done)
            assert np.array_equal(batch.next_obs[row], next_obs)
            if batch.named[row] < 0:
                assert np.array_equal(batch.next_instruction[row], episode.next_instructions[step + k - 1])


def test_n_step_needs_at_least_one_step() -> None:
    buffer, _ = _filled(capacity=300, episodes=5)
    with pytest.raises(ValueError, match="n_step"):
        buffer.sample(8, np.random.default_rng(0), n_step=0)


def test_a_buffer_of_format_1_still_loads() -> None:
    buffer, _ = _filled(capacity=2000, episodes=60, seed=9)
    meta, arrays = buffer.state()
    old = {k: v.copy() for k, v in arrays.items() if k not in ("names_goal", "first_achieved")}
    old["corrected_pool"] = old["corrected_pool"][:, :, 1, :].copy()  # one sentence per target
    loaded = ReplayBuffer.from_state({**meta, "format": 1}, old)
    pool = loaded.data["corrected_pool"][: loaded.high]
    for touched in range(3):
        assert np.array_equal(pool[:, :, touched], old["corrected_pool"])
    assert not loaded.data["names_goal"].any()
    batch = loaded.sample(256, np.random.default_rng(0), relabel_ratio=1.0, correction_share=1.0, ground_real=True)
    assert np.array_equal(batch.label, batch.named)


def _drop_at_the_end(_: int, episode: EpisodeData) -> None:
    if not episode.terminated[-1]:
        episode.fell = np.zeros(len(episode), dtype=bool)
        episode.fell[-1] = True  # the episode ended by dropping an object


def _lose_one_object_from_halfway(i: int, episode: EpisodeData) -> None:
    episode.lost = np.zeros_like(episode.achieved)
    episode.lost[len(episode) // 2 :, i % episode.achieved.shape[1]] = True


def _dropped(episode: EpisodeData, step: int, _: int) -> bool:
    return episode.fell is not None and bool(episode.fell[step])


def _lost(episode: EpisodeData, step: int, about: int) -> bool:
    return bool(episode.lost[step, about])


@pytest.mark.parametrize(
    ("setting", "edit", "ends"),
    [("falls_fail", _drop_at_the_end, _dropped), ("lost_fails", _lose_one_object_from_halfway, _lost)],
)
def test_a_failure_setting_marks_its_transitions_failed_and_done_unless_they_won(setting: str, edit, ends) -> None:  # type: ignore[no-untyped-def]
    """falls_fail: the step dropped an object; lost_fails: after it the object the sentence is about (the goal,
    or the relabelled target) is lost. (A fall ends its episode, so no relabelled target is won later.)"""
    buffer, added = _filled(5000, 200, seed=10, edit=edit)
    rng = np.random.default_rng(10)
    failed = {True: 0, False: 0}  # by whether the transition was relabelled
    for on in (False, True):
        batch = buffer.sample(1024, rng, relabel_ratio=0.5, **{setting: on})
        for row in range(1024):
            episode, step = _origin(batch, row, added)
            about = batch.named[row] if batch.relabelled[row] else episode.goal_index
            won = batch.reward[row] == 0.0
            assert batch.failed[row] == (on and ends(episode, step, about) and not won)
            assert batch.done[row] == (won or batch.failed[row])
            failed[bool(batch.relabelled[row])] += int(batch.failed[row])
    assert failed[False] > 20 and (failed[True] > 20 or setting == "falls_fail")
    batch = buffer.sample(512, rng, relabel_ratio=0.5, n_step=3, gamma=0.9, **{setting: True})
    assert batch.failed.any() and batch.done[batch.failed].all()
    for row in np.flatnonzero(batch.failed):  # judged at the last step the transition spans
        episode, step = _origin(batch, row, added)
        about = batch.named[row] if batch.relabelled[row] else episode.goal_index
        assert ends(episode, step + int(batch.steps[row]) - 1, about)


def _lose_two_objects(i: int, episode: EpisodeData) -> None:
    _lose_one_object_from_halfway(i, episode)
    episode.lost[3 * len(episode) // 4 :, (i + 1) % episode.achieved.shape[1]] = True


@pytest.mark.parametrize("n_step", [1, 3])
def test_knock_cost_is_paid_once_for_each_step_that_leaves_an_object_lost(n_step: int) -> None:
    """Whatever the transition's sentence is about, and discounted along an n-step transition; the draws and
    everything else in the batch are those of the same sample without the cost."""
    buffer, added = _filled(5000, 200, seed=13, edit=_lose_two_objects)
    free = buffer.sample(1024, np.random.default_rng(3), relabel_ratio=0.5, n_step=n_step, gamma=0.9)
    paid = buffer.sample(1024, np.random.default_rng(3), relabel_ratio=0.5, n_step=n_step, gamma=0.9, knock_cost=2.0)
    assert np.array_equal(free.slots, paid.slots) and np.array_equal(free.done, paid.done)
    charged = 0
    for row in range(1024):
        episode, step = _origin(free, row, added)
        lost = np.vstack([np.zeros_like(episode.lost[:1]), episode.lost])
        knocked = (lost[1:] & ~lost[:-1]).any(axis=1)
        spanned = range(step, step + int(free.steps[row]))
        cost = 2.0 * sum(0.9 ** (t - step) for t in spanned if knocked[t])
        assert free.reward[row] - paid.reward[row] == pytest.approx(cost, abs=1e-5)
        charged += cost > 0
    assert charged > 20


def test_a_buffer_saved_before_losses_were_recorded_reads_as_nothing_lost() -> None:
    buffer, _ = _filled(capacity=2000, episodes=60, seed=12)
    meta, arrays = buffer.state()
    loaded = ReplayBuffer.from_state({**meta, "format": 2}, {k: v for k, v in arrays.items() if k != "lost"})
    assert not loaded.data["lost"].any()
    assert not loaded.sample(256, np.random.default_rng(0), relabel_ratio=0.5, lost_fails=True).failed.any()


CHAINS = grammar_vocabulary(2)


def _two_mistakes_then_goal(rng: np.random.Generator, episode_id: int) -> EpisodeData:
    """Three distinct objects; the arm acts on both wrong ones (in a random order) and then on the goal."""
    episode = random_episode(rng, episode_id, steps=12)
    while len(set(episode.objects)) < 3:
        episode = random_episode(rng, episode_id, steps=12)
    wrong = [int(i) for i in rng.permutation(3) if i != episode.goal_index]
    achieved = np.zeros((12, 3), dtype=bool)
    achieved[3:, wrong[0]] = True
    achieved[7:, wrong[1]] = True
    achieved[11, episode.goal_index] = True
    tokens = np.pad(episode.instructions, ((0, 0), (0, CHAINS.max_length - VOCAB.max_length)))
    return replace(
        episode,
        achieved=achieved,
        rewards=np.where(achieved[:, episode.goal_index], 0.0, -1.0).astype(np.float32),
        terminated=achieved[:, episode.goal_index].copy(),
        instructions=tokens,
        next_instructions=tokens.copy(),
    )


def test_a_buffer_that_relabels_chains_corrects_each_wrong_object_in_turn() -> None:
    rng = np.random.default_rng(8)
    episodes = {i: _two_mistakes_then_goal(rng, i) for i in range(60)}
    corrections = {}
    for chain in (1, 2):
        buffer = ReplayBuffer(5000, OBS_DIM, ACTION_DIM, max_objects=3, vocabulary=CHAINS, seed=3, chain=chain)
        for episode in episodes.values():
            buffer.add_episode(episode)
        batch = buffer.sample(512, np.random.default_rng(0), relabel_ratio=1.0, correction_share=1.0)
        counts = []
        for row in np.flatnonzero(batch.relabelled):
            episode, _ = _origin(batch, row, episodes)
            target = int(batch.named[row])  # the arm acted on all three: both others are wrong for any target
            wrong = [int(i) for i in np.argsort(np.argmax(episode.achieved, axis=0)) if i != target]
            text = CHAINS.decode(batch.instruction[row])
            _, spoken = split_chain(text)
            counts.append(len(spoken))
            assert chain_referents(text, episode.task, episode.objects, wrong)[-1] == [target], text
        corrections[chain] = counts
    assert len(corrections[2]) > 100 and set(corrections[2]) == {2}
    assert set(corrections[1]) == {1}
    assert ReplayBuffer.from_state(*buffer.state()).chain == 2
