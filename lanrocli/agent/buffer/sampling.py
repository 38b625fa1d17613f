"""A batch read from the replay buffer's arrays at the slots drawn for it: hindsight sentences given to some
transitions, and rewards and done flags recomputed for them. :meth:`ReplayBuffer.sample` draws the slots and
says what each setting does."""

from __future__ import annotations

import numpy as np

from lanrocli.agent.buffer.transitions import NEVER, NO_OBJECT, Batch
from lanrocli.agent.settings import BufferSettings
from lanrocli.core.reward import FAILURE_REWARD, SUCCESS_REWARD


def sampled_batch(
    data: dict[str, np.ndarray], idx: np.ndarray, rng: np.random.Generator, pool_rows: int, settings: BufferSettings
) -> Batch:
    """The transitions stored at the slots ``idx`` (in a buffer whose sentence pools hold ``pool_rows`` rows),
    relabelled as ``settings`` ask."""
    batch_size = idx.size
    instruction = data["instruction"][idx].astype(np.int64)
    next_instruction = data["next_instruction"][idx].astype(np.int64)
    reward = data["reward"][idx]
    done = data["terminated"][idx]

    relabel = (data["future_count"][idx] > 0) & (rng.random(batch_size) < settings.relabel_ratio)
    named = np.full(batch_size, -1, dtype=np.int64)
    rows = idx[relabel]
    if rows.size:
        step = data["achieving_slot"][data["future_first"][rows] + rng.integers(0, data["future_count"][rows])]
        candidates = data["achieved"][step] & data["identifiable"][step]
        if settings.fresh_targets:
            candidates &= ~_step_before(data, "achieved", rows)
        found = candidates.any(axis=1)
        relabel[relabel] = found
        rows, candidates = rows[found], candidates[found]
    if rows.size:
        target = np.argmax(np.where(candidates, rng.random(candidates.shape), -1.0), axis=1)
        pool_row = data["episode_start"][rows] + rng.integers(0, np.minimum(data["episode_length"][rows], pool_rows))
        touched, has_other = _touched(data, rows, target, rng)
        corrected = (rng.random(rows.size) < settings.corrected_share) & has_other
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
    if settings.ground_real:
        real = ~relabel & data["names_goal"][idx]
        label[real] = data["goal_index"][idx[real]]

    return Batch(
        obs=data["obs"][idx],
        instruction=instruction,
        action=data["action"][idx],
        reward=reward,
        next_obs=data["next_obs"][idx],
        next_instruction=next_instruction,
        done=done,
        named=named,
        label=label,
        slots=idx,
    )


def _step_before(data: dict[str, np.ndarray], name: str, slots: np.ndarray) -> np.ndarray:
    """The per-object flags ``data[name]`` after the step before each slot's; none at an episode's first step."""
    first = data["episode_start"][slots] == slots
    return data[name][np.maximum(slots - 1, 0)] & ~first[..., None]


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
