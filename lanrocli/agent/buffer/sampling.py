"""A batch read from the replay buffer's arrays at the slots drawn for it: hindsight sentences given to some
transitions, rewards and done flags recomputed for them, and n-step returns. :meth:`ReplayBuffer.sample`
draws the slots and says what each option does."""

from __future__ import annotations

import numpy as np

from lanrocli.agent.buffer.transitions import NEVER, NO_OBJECT, Batch
from lanrocli.core.reward import FAILURE_REWARD, SUCCESS_REWARD


def sampled_batch(
    data: dict[str, np.ndarray],
    idx: np.ndarray,
    rng: np.random.Generator,
    pool_rows: int,
    relabel_ratio: float,
    correction_share: float,
    n_step: int,
    gamma: float,
    fresh_targets: bool,
    ground_real: bool,
    falls_fail: bool,
    lost_fails: bool,
    knock_cost: float,
) -> Batch:
    """The transitions stored at the slots ``idx``, relabelled and extended as :meth:`ReplayBuffer.sample`
    was asked."""
    batch_size = idx.size
    instruction = data["instruction"][idx].astype(np.int64)
    next_instruction = data["next_instruction"][idx].astype(np.int64)
    reward = data["reward"][idx]
    done = data["terminated"][idx]

    relabel = (data["future_count"][idx] > 0) & (rng.random(batch_size) < relabel_ratio)
    named = np.full(batch_size, -1, dtype=np.int64)
    target = np.zeros(0, dtype=np.int64)
    rows = idx[relabel]
    if rows.size:
        step = data["achieving_slot"][data["future_first"][rows] + rng.integers(0, data["future_count"][rows])]
        candidates = data["achieved"][step] & data["identifiable"][step]
        if fresh_targets:
            candidates &= ~_step_before(data, "achieved", rows)
        found = candidates.any(axis=1)
        relabel[relabel] = found
        rows, candidates = rows[found], candidates[found]
    if rows.size:
        target = np.argmax(np.where(candidates, rng.random(candidates.shape), -1.0), axis=1)
        pool_row = data["episode_start"][rows] + rng.integers(0, np.minimum(data["episode_length"][rows], pool_rows))
        touched, has_other = _touched(data, rows, target, rng)
        corrected = (rng.random(rows.size) < correction_share) & has_other
        sentence = np.where(
            corrected[:, None], data["corrected_pool"][pool_row, target, touched], data["plain_pool"][pool_row, target]
        )
        success = data["achieved"][rows, target]
        instruction[relabel] = sentence
        next_instruction[relabel] = sentence
        reward[relabel] = np.where(success, SUCCESS_REWARD, FAILURE_REWARD)
        done[relabel] = success
        named[relabel] = target
    label = named.copy()
    if ground_real:
        real = ~relabel & data["names_goal"][idx]
        label[real] = data["goal_index"][idx[real]]

    batch = Batch(
        obs=data["obs"][idx],
        instruction=instruction,
        action=data["action"][idx],
        reward=reward,
        next_obs=data["next_obs"][idx],
        next_instruction=next_instruction,
        done=done,
        named=named,
        label=label,
        failed=np.zeros(batch_size, dtype=bool),
        slots=idx,
        steps=np.ones(batch_size, dtype=np.int64),
    )
    if n_step > 1:
        _extend(data, batch, relabel, target, n_step, gamma)
    final = batch.slots + batch.steps - 1
    if knock_cost:
        batch.reward -= np.float32(knock_cost) * _knocks(data, batch.slots, batch.steps, gamma)
    if falls_fail:
        batch.failed |= data["fell"][final] & ~batch.done
    if lost_fails:
        about = np.where(relabel, named, data["goal_index"][idx].astype(np.int64))
        batch.failed |= data["lost"][final, about] & ~batch.done
    batch.done = batch.done | batch.failed
    return batch


def _step_before(data: dict[str, np.ndarray], name: str, slots: np.ndarray) -> np.ndarray:
    """The per-object flags ``data[name]`` after the step before each slot's; none at an episode's first step."""
    first = data["episode_start"][slots] == slots
    return data[name][np.maximum(slots - 1, 0)] & ~first[..., None]


def _knocks(data: dict[str, np.ndarray], slots: np.ndarray, steps: np.ndarray, gamma: float) -> np.ndarray:
    """Per transition, its steps at which some object became lost (it was not after the step before, nor at
    the episode's start), each discounted by ``gamma`` to the power of its place in the transition."""
    offsets = np.arange(int(steps.max()))
    at = np.minimum(slots[:, None] + offsets, (slots + steps - 1)[:, None])  # an episode's steps are contiguous
    knocked = (data["lost"][at] & ~_step_before(data, "lost", at)).any(axis=-1)
    return np.where(offsets < steps[:, None], knocked * gamma**offsets, 0.0).sum(axis=1).astype(np.float32)


def _touched(
    data: dict[str, np.ndarray], rows: np.ndarray, target: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Per relabelled transition, the object other than its target that the arm achieved the task on
    first in the episode, else a uniformly drawn other object; and whether the scene has another."""
    first = data["first_achieved"][rows].copy()
    first[np.arange(rows.size), target] = NEVER
    present = data["objects"][rows, :, 0] != NO_OBJECT
    n = present.sum(axis=1)
    drawn = (target + 1 + rng.integers(0, np.maximum(n - 1, 1))) % np.maximum(n, 1)
    touched = np.where(first.min(axis=1) < NEVER, np.argmin(first, axis=1), drawn)
    return touched, n > 1


def _extend(
    data: dict[str, np.ndarray], batch: Batch, relabel: np.ndarray, target: np.ndarray, n_step: int, gamma: float
) -> None:
    """Turn one-step transitions into n-step ones, in place.

    A transition at step t spans steps t..t+k-1, where k is ``n_step``, cut short at the episode's last
    step and at the first step that achieves its goal (which then ends it as done). A stored transition
    keeps the goal the episode gave it step by step, so the rewards after a correction are those of the
    corrected goal, as the one-step target's bootstrap already reads the corrected sentence; a relabelled
    one keeps its sentence, and its rewards and done flags are recomputed from the stored ``achieved``
    flags of the object it names, as for one step. The return sums the rewards discounted by ``gamma``;
    the later steps' entropy bonus is left out, as is usual for n-step SAC.
    """
    slots = batch.slots
    last = data["episode_start"][slots] + data["episode_length"][slots] - 1
    offsets = np.arange(n_step)
    window = np.minimum(slots[:, None] + offsets, last[:, None])  # [B, n], repeats the last step past the end
    inside = slots[:, None] + offsets <= last[:, None]
    reward = data["reward"][window].astype(np.float64)
    achieved = data["terminated"][window].copy()
    if target.size:
        hit = data["achieved"][window[relabel], target[:, None]]
        achieved[relabel] = hit
        reward[relabel] = np.where(hit, SUCCESS_REWARD, FAILURE_REWARD)
    ends = achieved & inside
    done = ends.any(axis=1)
    steps = np.where(done, np.argmax(ends, axis=1) + 1, inside.sum(axis=1))
    counted = offsets[None, :] < steps[:, None]
    batch.reward = (np.where(counted, reward * gamma**offsets, 0.0).sum(axis=1)).astype(np.float32)
    batch.done = done
    batch.steps = steps.astype(np.int64)
    final = slots + steps - 1
    batch.next_obs = data["next_obs"][final]
    batch.next_instruction[~relabel] = data["next_instruction"][final[~relabel]].astype(np.int64)
