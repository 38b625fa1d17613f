"""The replay buffer: whole episodes in flat preallocated arrays, sampled with hindsight language relabelling.

Transitions live in a ring of ``capacity`` slots. An episode always occupies consecutive slots; when it
does not fit before the end of the ring, writing wraps to slot 0 and the unused tail is retired. Writing
over any slot of an older episode retires that whole episode, so a sample never mixes an episode with the
one that half overwrote it: relabelling looks ahead within the episode, which would otherwise read another
episode's future.

Relabelling works on the sampled copies, never on the stored arrays. For each episode the buffer keeps, per
slot, where the episode starts and how long it is, which later steps achieved the task on an object that a
sentence can single out, and a small pool of such sentences per object (see :mod:`lanrocli.agent.relabel`).
Sampling then needs only vectorised indexing.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from lanrocli.agent.relabel import sentence_pool
from lanrocli.language.holdout import NOTHING_HELD_OUT, Holdout
from lanrocli.language import TASKS, ObjectProps, Vocabulary, check_task, grammar_vocabulary
from lanrocli.reward import FAILURE_REWARD, SUCCESS_REWARD

NO_OBJECT = np.iinfo(np.uint8).max
"""Property index stored for an object slot that the episode's scene leaves empty."""

NEVER = np.iinfo(np.int32).max
"""``first_achieved`` of an object the episode never achieved the task on."""

_FORMAT = 2
"""1: corrected sentences by target only, and no ``names_goal`` or ``first_achieved``; still read."""


@dataclass
class EpisodeData:
    """One complete (or truncated) episode of T steps, as the training loop collected it.

    ``instructions[t]`` is the goal sentence read with ``observations[t]`` and ``next_instructions[t]``
    the one read with ``next_observations[t]``; they differ at the step a correction is spoken.
    ``achieved[t, k]``: the task condition holds for object k after step t (the environment's
    ``info["achieved"]``). ``terminated[t]``: step t ended the episode by success (not by the time limit).
    ``objects`` are in observation order, as ``info["objects"]`` lists them.
    """

    observations: np.ndarray  # float32 [T, N]
    next_observations: np.ndarray  # float32 [T, N]
    instructions: np.ndarray  # int [T, L]
    next_instructions: np.ndarray  # int [T, L]
    actions: np.ndarray  # float32 [T, A]
    rewards: np.ndarray  # float32 [T]
    terminated: np.ndarray  # bool [T]
    achieved: np.ndarray  # bool [T, n_objects]
    goal_index: int
    objects: tuple[ObjectProps, ...]
    task: str
    fell: np.ndarray | None = None  # bool [T]: step t ended the episode by dropping an object; None: never
    correction_episode: bool = False
    """Whether the instructor set this episode up for a correction: its instruction singles out the goal
    only once the correction is spoken (the environment's ``info["challenge"]`` is not None)."""

    def __len__(self) -> int:
        return int(self.observations.shape[0])


@dataclass
class Batch:
    """Sampled transitions. ``done``: the step ended by success. ``named``: for a relabelled transition the
    object slot its new sentence singles out, -1 for the others. ``label``: the object slot the
    transition's sentence singles out where that is known (``named``, and with ``ground_real`` sampling
    the goal of a stored transition whose sentence names it), -1 elsewhere; the attention is taught on
    it. ``failed``: with ``falls_fail`` sampling, the transition's last step dropped an object off the table
    without winning, so the episode is lost for good (``done`` is then set too). ``slots``: where in the
    buffer each transition is stored, to look up what the batch does not carry.

    ``steps``: how many stored steps each transition spans. With n-step sampling ``reward`` is the return
    discounted over those steps, ``next_obs`` and ``next_instruction`` are read after the last of them, and
    the Bellman target discounts its bootstrap by ``gamma ** steps``."""

    obs: np.ndarray  # float32 [B, N]
    instruction: np.ndarray  # int64 [B, L]
    action: np.ndarray  # float32 [B, A]
    reward: np.ndarray  # float32 [B]
    next_obs: np.ndarray  # float32 [B, N]
    next_instruction: np.ndarray  # int64 [B, L]
    done: np.ndarray  # bool [B]
    named: np.ndarray  # int64 [B]
    label: np.ndarray  # int64 [B]
    failed: np.ndarray  # bool [B]
    slots: np.ndarray  # int64 [B]
    steps: np.ndarray  # int64 [B], 1 for one-step transitions

    @property
    def relabelled(self) -> np.ndarray:
        """bool [B]: which transitions got a hindsight sentence."""
        return self.named >= 0


# The stored arrays: name -> (dtype, shape after the slot axis, in terms of the buffer's dimensions).
def _layout(obs_dim: int, action_dim: int, max_objects: int, length: int) -> dict[str, tuple[type, tuple[int, ...]]]:
    return {
        "obs": (np.float32, (obs_dim,)),
        "next_obs": (np.float32, (obs_dim,)),
        "action": (np.float32, (action_dim,)),
        "reward": (np.float32, ()),
        "terminated": (np.bool_, ()),
        "instruction": (np.uint8, (length,)),
        "next_instruction": (np.uint8, (length,)),
        "achieved": (np.bool_, (max_objects,)),
        "fell": (np.bool_, ()),
        "names_goal": (np.bool_, ()),  # the sentence read with obs singles out the goal
        "first_achieved": (np.int32, (max_objects,)),  # the episode's first step achieving each object
        "goal_index": (np.uint8, ()),
        "objects": (np.uint8, (max_objects, 2)),
        "task": (np.uint8, ()),
        "episode_start": (np.int32, ()),
        "episode_length": (np.int32, ()),
        # Relabelling: the achieving steps of an episode are listed (as slots) in the episode's own slots;
        # for step t, future_first/future_count select those at or after t.
        "achieving_slot": (np.int32, ()),
        "future_first": (np.int32, ()),
        "future_count": (np.int32, ()),
        "identifiable": (np.bool_, (max_objects,)),
        "plain_pool": (np.uint8, (max_objects, length)),
        "corrected_pool": (np.uint8, (max_objects, max_objects, length)),  # by target, touched object
        "valid": (np.bool_, ()),
    }


class ReplayBuffer:
    """Episodes in a ring of ``capacity`` transitions, with hindsight language relabelling.

    ``pool_rows``: relabelling sentences drawn per object and style when an episode is added (fewer for
    episodes shorter than that, as the pool is stored in the episode's own slots). ``negations``: whether
    corrected relabelling sentences may use ``not``; ``holdout``: what they may never say. ``seed`` drives those draws; the generator's state is
    saved with the buffer so a resumed run draws the same sentences.

    The arrays are allocated with ``np.zeros``, which the operating system backs with memory only as slots
    are first written, so a large capacity costs little until it fills.
    """

    def __init__(
        self,
        capacity: int,
        obs_dim: int,
        action_dim: int,
        max_objects: int = 3,
        vocabulary: Vocabulary | None = None,
        pool_rows: int = 16,
        negations: bool = True,
        seed: int = 0,
        holdout: Holdout = NOTHING_HELD_OUT,
    ) -> None:
        vocabulary = vocabulary if vocabulary is not None else grammar_vocabulary()
        if len(vocabulary) > np.iinfo(np.uint8).max + 1:
            raise ValueError(f"a vocabulary of {len(vocabulary)} words does not fit the buffer's uint8 token ids")
        if not 1 <= capacity < 2**31 or pool_rows < 1 or max_objects < 1:
            raise ValueError("capacity (below 2**31, slots are int32), pool_rows and max_objects must be positive")
        self.capacity = capacity
        self.obs_dim = obs_dim
        self.action_dim = action_dim
        self.max_objects = max_objects
        self.vocabulary = vocabulary
        self.pool_rows = pool_rows
        self.negations = negations
        self.holdout = holdout
        self.rng = np.random.default_rng(seed)
        self.position = 0  # next slot to write
        self.high = 0  # one past the highest slot ever written: samples are drawn below it
        self.size = 0  # valid transitions
        self.episodes_added = 0
        self._relabelable: np.ndarray | None = None  # slots relabelling can turn into successes; None: stale
        layout = _layout(obs_dim, action_dim, max_objects, vocabulary.max_length)
        self.data: dict[str, np.ndarray] = {
            name: np.zeros((capacity, *shape), dtype=dtype) for name, (dtype, shape) in layout.items()
        }

    def __len__(self) -> int:
        return self.size

    @property
    def bytes_per_transition(self) -> int:
        """Memory one slot takes once written, over all the stored arrays."""
        return sum(array[0].nbytes for array in self.data.values())

    # -- writing -------------------------------------------------------------------------------------------

    def add_episode(self, episode: EpisodeData) -> None:
        """Store one episode, retiring whole older episodes where it overwrites them."""
        steps = len(episode)
        objects = episode.objects
        self._check(episode, steps, len(objects))
        if steps > self.capacity:
            raise ValueError(f"an episode of {steps} steps does not fit a buffer of {self.capacity} transitions")
        if self.position + steps > self.capacity:
            self._retire(self.position, self.capacity)
            self.position = 0
        lo, hi = self.position, self.position + steps
        self._retire(lo, hi)

        n = len(objects)
        d = self.data
        d["obs"][lo:hi] = episode.observations
        d["next_obs"][lo:hi] = episode.next_observations
        d["action"][lo:hi] = episode.actions
        d["reward"][lo:hi] = episode.rewards
        d["terminated"][lo:hi] = episode.terminated
        d["fell"][lo:hi] = False if episode.fell is None else episode.fell
        d["instruction"][lo:hi] = episode.instructions
        d["next_instruction"][lo:hi] = episode.next_instructions
        d["achieved"][lo:hi] = False
        d["achieved"][lo:hi, :n] = episode.achieved
        corrected_yet = (episode.instructions != episode.instructions[0]).any(axis=1)
        d["names_goal"][lo:hi] = corrected_yet | (not episode.correction_episode)
        ever = episode.achieved.any(axis=0)
        d["first_achieved"][lo:hi] = NEVER
        d["first_achieved"][lo:hi, :n] = np.where(ever, np.argmax(episode.achieved, axis=0), NEVER)
        d["goal_index"][lo:hi] = episode.goal_index
        d["objects"][lo:hi] = NO_OBJECT
        d["objects"][lo:hi, :n] = [o.indices for o in objects]
        d["task"][lo:hi] = TASKS.index(episode.task)
        d["episode_start"][lo:hi] = lo
        d["episode_length"][lo:hi] = steps

        rows = min(steps, self.pool_rows)
        pool = sentence_pool(episode.task, objects, rows, self.vocabulary, self.negations, self.rng, self.holdout)
        d["identifiable"][lo:hi] = False
        d["identifiable"][lo:hi, :n] = pool.identifiable
        d["plain_pool"][lo:hi] = 0
        d["corrected_pool"][lo:hi] = 0
        d["plain_pool"][lo : lo + rows, :n] = pool.plain
        d["corrected_pool"][lo : lo + rows, :n, :n] = pool.corrected

        achieving = np.flatnonzero((episode.achieved & pool.identifiable).any(axis=1))
        first = np.searchsorted(achieving, np.arange(steps))
        d["achieving_slot"][lo:hi] = 0
        d["achieving_slot"][lo : lo + achieving.size] = lo + achieving
        d["future_first"][lo:hi] = lo + first
        d["future_count"][lo:hi] = achieving.size - first

        d["valid"][lo:hi] = True
        self._relabelable = None
        self.size += steps
        self.position = hi
        self.high = max(self.high, hi)
        self.episodes_added += 1

    def _check(self, episode: EpisodeData, steps: int, n_objects: int) -> None:
        check_task(episode.task)
        length = self.vocabulary.max_length
        expected = {
            "observations": (steps, self.obs_dim),
            "next_observations": (steps, self.obs_dim),
            "instructions": (steps, length),
            "next_instructions": (steps, length),
            "actions": (steps, self.action_dim),
            "rewards": (steps,),
            "terminated": (steps,),
            "achieved": (steps, n_objects),
        }
        for name, shape in expected.items():
            got = np.shape(getattr(episode, name))
            if got != shape:
                raise ValueError(f"episode {name} has shape {got}, expected {shape}")
        if steps < 1:
            raise ValueError("an episode needs at least one step")
        if not 1 <= n_objects <= self.max_objects:
            raise ValueError(f"an episode has {n_objects} objects; this buffer holds 1 to {self.max_objects}")
        if not 0 <= episode.goal_index < n_objects:
            raise ValueError(f"goal_index {episode.goal_index} is not one of the {n_objects} objects")

    def _retire(self, lo: int, hi: int) -> None:
        """Invalidate every episode that has a slot in [lo, hi), all of its slots."""
        valid = self.data["valid"]
        if lo >= hi:
            return
        if valid[lo]:
            lo = int(self.data["episode_start"][lo])
        if valid[hi - 1]:
            hi = int(self.data["episode_start"][hi - 1] + self.data["episode_length"][hi - 1])
        self.size -= int(np.count_nonzero(valid[lo:hi]))
        valid[lo:hi] = False

    # -- sampling ------------------------------------------------------------------------------------------

    def sample(
        self,
        batch_size: int,
        rng: np.random.Generator,
        relabel_ratio: float = 0.0,
        correction_share: float = 0.0,
        hindsight_share: float = 0.0,
        n_step: int = 1,
        gamma: float = 1.0,
        fresh_targets: bool = False,
        ground_real: bool = False,
        falls_fail: bool = False,
    ) -> Batch:
        """``batch_size`` transitions drawn with replacement: a share ``hindsight_share`` (binomially) from
        the transitions whose episode achieves the task on an identifiable object at that step or later, the
        rest uniformly from all stored ones.

        With probability ``relabel_ratio`` a transition whose episode later achieves the task on an
        identifiable object gets a sentence for such an object: a step t' is drawn uniformly among the
        steps at or after t that achieved the task on one, then one of those objects uniformly. Its reward
        and done flag are recomputed from the stored ``achieved`` flags at step t. With ``fresh_targets``
        only objects the task did not already hold for before step t are targets (a target that holds
        already makes a transition that is won whatever the action); a transition left without one keeps
        its own sentence. A share ``correction_share`` of the relabelled sentences are corrections rather
        than plain instructions: those written for the object the arm acted on first in the episode,
        other than the target (where there is none, another object drawn uniformly).

        ``ground_real``: a stored transition whose sentence singles out its goal (every step of a plain
        episode, and the steps after the correction of a correction episode) is labelled with the goal
        for the attention loss; one whose correction is still pending never is.

        ``falls_fail``: a transition whose last step dropped an object off the table, where its goal is
        not won at that step, is ``failed`` and ``done``: the environment ends such an episode, and the
        learner is to value what follows as failure for ever, not as the time limit it otherwise resembles.

        With ``n_step`` above 1 each transition spans up to ``n_step`` stored steps of its episode (fewer where
        the episode ends first, or where its goal, the relabelled one included, is achieved first): see
        :meth:`_extend`; ``gamma`` discounts the rewards along the way.
        """
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        if n_step < 1:
            raise ValueError(f"n_step must be at least 1, got {n_step}")
        d = self.data
        idx = self._draw(batch_size, rng, hindsight_share)
        instruction = d["instruction"][idx].astype(np.int64)
        next_instruction = d["next_instruction"][idx].astype(np.int64)
        reward = d["reward"][idx]
        done = d["terminated"][idx]

        relabel = (d["future_count"][idx] > 0) & (rng.random(batch_size) < relabel_ratio)
        named = np.full(batch_size, -1, dtype=np.int64)
        target = np.zeros(0, dtype=np.int64)
        rows = idx[relabel]
        if rows.size:
            step = d["achieving_slot"][d["future_first"][rows] + rng.integers(0, d["future_count"][rows])]
            candidates = d["achieved"][step] & d["identifiable"][step]
            if fresh_targets:
                at_start = d["episode_start"][rows] == rows
                candidates &= ~(d["achieved"][np.maximum(rows - 1, 0)] & ~at_start[:, None])
            found = candidates.any(axis=1)
            relabel[relabel] = found
            rows, candidates = rows[found], candidates[found]
        if rows.size:
            target = np.argmax(np.where(candidates, rng.random(candidates.shape), -1.0), axis=1)
            pool_row = d["episode_start"][rows] + rng.integers(0, np.minimum(d["episode_length"][rows], self.pool_rows))
            touched, has_other = self._touched(rows, target, rng)
            corrected = (rng.random(rows.size) < correction_share) & has_other
            sentence = np.where(
                corrected[:, None], d["corrected_pool"][pool_row, target, touched], d["plain_pool"][pool_row, target]
            )
            success = d["achieved"][rows, target]
            instruction[relabel] = sentence
            next_instruction[relabel] = sentence
            reward[relabel] = np.where(success, SUCCESS_REWARD, FAILURE_REWARD)
            done[relabel] = success
            named[relabel] = target
        label = named.copy()
        if ground_real:
            real = ~relabel & d["names_goal"][idx]
            label[real] = d["goal_index"][idx[real]]

        batch = Batch(
            obs=d["obs"][idx],
            instruction=instruction,
            action=d["action"][idx],
            reward=reward,
            next_obs=d["next_obs"][idx],
            next_instruction=next_instruction,
            done=done,
            named=named,
            label=label,
            failed=np.zeros(batch_size, dtype=bool),
            slots=idx,
            steps=np.ones(batch_size, dtype=np.int64),
        )
        if n_step > 1:
            self._extend(batch, relabel, target, n_step, gamma)
        if falls_fail:
            batch.failed = d["fell"][batch.slots + batch.steps - 1] & ~batch.done
            batch.done = batch.done | batch.failed
        return batch

    def _touched(self, rows: np.ndarray, target: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Per relabelled transition, the object other than its target that the arm achieved the task on
        first in the episode, else a uniformly drawn other object; and whether the scene has another."""
        first = self.data["first_achieved"][rows].copy()
        first[np.arange(rows.size), target] = NEVER
        present = self.data["objects"][rows, :, 0] != NO_OBJECT
        n = present.sum(axis=1)
        drawn = (target + 1 + rng.integers(0, np.maximum(n - 1, 1))) % np.maximum(n, 1)
        touched = np.where(first.min(axis=1) < NEVER, np.argmin(first, axis=1), drawn)
        return touched, n > 1

    def _extend(self, batch: Batch, relabel: np.ndarray, target: np.ndarray, n_step: int, gamma: float) -> None:
        """Turn one-step transitions into n-step ones, in place.

        A transition at step t spans steps t..t+k-1, where k is ``n_step``, cut short at the episode's last
        step and at the first step that achieves its goal (which then ends it as done). A stored transition
        keeps the goal the episode gave it step by step, so the rewards after a correction are those of the
        corrected goal, as the one-step target's bootstrap already reads the corrected sentence; a relabelled
        one keeps its sentence, and its rewards and done flags are recomputed from the stored ``achieved``
        flags of the object it names, as for one step. The return sums the rewards discounted by ``gamma``;
        the later steps' entropy bonus is left out, as is usual for n-step SAC.
        """
        d = self.data
        slots = batch.slots
        last = d["episode_start"][slots] + d["episode_length"][slots] - 1
        offsets = np.arange(n_step)
        window = np.minimum(slots[:, None] + offsets, last[:, None])  # [B, n], repeats the last step past the end
        inside = slots[:, None] + offsets <= last[:, None]
        reward = d["reward"][window].astype(np.float64)
        achieved = d["terminated"][window].copy()
        if target.size:
            hit = d["achieved"][window[relabel], target[:, None]]
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
        batch.next_obs = d["next_obs"][final]
        batch.next_instruction[~relabel] = d["next_instruction"][final[~relabel]].astype(np.int64)

    def _draw(self, batch_size: int, rng: np.random.Generator, hindsight_share: float) -> np.ndarray:
        if hindsight_share == 0.0:
            return self._draw_valid(batch_size, rng)
        if self._relabelable is None:  # listed once per added episode, not per batch
            high = self.high
            self._relabelable = np.flatnonzero(self.data["valid"][:high] & (self.data["future_count"][:high] > 0))
        n_hindsight = rng.binomial(batch_size, hindsight_share) if self._relabelable.size else 0
        hindsight = self._relabelable[rng.integers(0, self._relabelable.size, size=n_hindsight)]
        return np.concatenate([hindsight, self._draw_valid(batch_size - n_hindsight, rng)])

    def _draw_valid(self, batch_size: int, rng: np.random.Generator) -> np.ndarray:
        """Uniform slots among the valid ones, by rejection: invalid slots are at most a tail and a
        retired remainder of an episode each, so one round nearly always suffices."""
        valid = self.data["valid"]
        chosen = np.empty(0, dtype=np.int64)
        while chosen.size < batch_size:
            draw = rng.integers(0, self.high, size=batch_size)
            chosen = np.concatenate([chosen, draw[valid[draw]]])
        return chosen[:batch_size]

    # -- state -------------------------------------------------------------------------------------------

    def state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """What :meth:`from_state` needs to continue exactly: settings and counters as plain data, and the
        arrays up to the highest slot ever written. The arrays are views, not copies, so writing a large
        buffer to a file does not first double it in memory; where it is written is the caller's business."""
        meta = {
            "format": _FORMAT,
            "capacity": self.capacity,
            "obs_dim": self.obs_dim,
            "action_dim": self.action_dim,
            "max_objects": self.max_objects,
            "vocabulary": self.vocabulary.to_dict(),
            "pool_rows": self.pool_rows,
            "negations": self.negations,
            "holdout": self.holdout.to_dict(),
            "position": self.position,
            "high": self.high,
            "size": self.size,
            "episodes_added": self.episodes_added,
            "rng": self.rng.bit_generator.state,
        }
        return meta, {name: array[: self.high] for name, array in self.data.items()}

    @classmethod
    def from_state(cls, meta: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> ReplayBuffer:
        """The buffer that :meth:`state` described. ``arrays`` may hold more than the buffer's arrays, and
        may be an open ``np.load`` archive, which then reads each array only as it is copied in."""
        if meta["format"] not in (1, _FORMAT):
            raise ValueError(f"replay buffer file format {meta['format']} is not {_FORMAT}")
        buffer = cls(
            capacity=meta["capacity"],
            obs_dim=meta["obs_dim"],
            action_dim=meta["action_dim"],
            max_objects=meta["max_objects"],
            vocabulary=Vocabulary.from_dict(meta["vocabulary"]),
            pool_rows=meta["pool_rows"],
            negations=meta["negations"],
            holdout=Holdout.from_dict(meta.get("holdout")),
        )
        high = meta["high"]
        for name, array in buffer.data.items():
            if meta["format"] == 1 and name in _ADDED_IN_2:
                _ADDED_IN_2[name](array[:high], arrays)
            else:
                array[:high] = arrays[name]
        buffer.rng.bit_generator.state = meta["rng"]
        buffer.position = meta["position"]
        buffer.high = high
        buffer.size = meta["size"]
        buffer.episodes_added = meta["episodes_added"]
        return buffer


def _read_pool_of_format_1(array: np.ndarray, arrays: Mapping[str, np.ndarray]) -> None:
    """Format 1 drew one corrected sentence per target: it serves every touched object."""
    array[:] = np.asarray(arrays["corrected_pool"])[:, :, None, :]


_ADDED_IN_2: dict[str, Callable[[np.ndarray, Mapping[str, np.ndarray]], None]] = {
    "corrected_pool": _read_pool_of_format_1,
    # What format 1 did not record reads as not known: no real transition is labelled for the attention,
    # and relabelled corrections draw the touched object uniformly.
    "names_goal": lambda array, _: array.fill(False),
    "fell": lambda array, _: array.fill(False),
    "first_achieved": lambda array, _: array.fill(NEVER),
}
