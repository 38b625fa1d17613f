"""The replay buffer: whole episodes in flat preallocated arrays, sampled with hindsight language relabelling.

Transitions live in a ring of ``capacity`` slots. An episode always occupies consecutive slots; when it
does not fit before the end of the ring, writing wraps to slot 0 and the unused tail is retired. Writing
over any slot of an older episode retires that whole episode, so a sample never mixes an episode with the
one that half overwrote it: relabelling looks ahead within the episode, which would otherwise read another
episode's future.

Relabelling works on the sampled copies, never on the stored arrays. For each episode the buffer keeps, per
slot, where the episode starts and how long it is, which later steps achieved the task on an object that a
sentence can single out, and a small pool of such sentences per object (see :mod:`lanrocli.agent.buffer.relabel`).
Sampling then needs only vectorised indexing.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from lanrocli.agent.buffer.relabel import sentence_pool
from lanrocli.agent.buffer.sampling import sampled_batch
from lanrocli.agent.buffer.transitions import NEVER, NO_OBJECT, Batch, EpisodeData, stored_arrays
from lanrocli.agent.settings import BufferSettings
from lanrocli.language import TASKS, Vocabulary, check_task, grammar_vocabulary
from lanrocli.language.holdout import NOTHING_HELD_OUT, Holdout

_FORMAT = 3
"""The version of :meth:`ReplayBuffer.state`'s layout, which :meth:`ReplayBuffer.from_state` checks."""


class ReplayBuffer:
    """Episodes in a ring of ``capacity`` transitions, with hindsight language relabelling.

    ``pool_rows``: relabelling sentences drawn per object and style when an episode is added (fewer for
    episodes shorter than that, as the pool is stored in the episode's own slots). ``negations``: whether
    corrected relabelling sentences may use ``not``; ``holdout``: what they may never say. ``seed`` drives those
    draws; the generator's state is saved with the buffer so a resumed run draws the same sentences.

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
        layout = stored_arrays(obs_dim, action_dim, max_objects, vocabulary.max_length)
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

    def sample(self, batch_size: int, rng: np.random.Generator, settings: BufferSettings) -> Batch:
        """``batch_size`` transitions drawn with replacement: a share ``settings.hindsight_share`` (binomially)
        from the transitions whose episode achieves the task on an identifiable object at that step or later,
        the rest uniformly from all stored ones. The settings' other fields say how they are relabelled:

        With probability ``relabel_ratio`` a transition whose episode later achieves the task on an
        identifiable object gets a sentence for such an object: a step t' is drawn uniformly among the
        steps at or after t that achieved the task on one, then one of those objects uniformly. Its reward
        and done flag are recomputed from the stored ``achieved`` flags at step t. With ``fresh_targets``
        only objects the task did not already hold for before step t are targets (a target that holds
        already makes a transition that is won whatever the action); a transition left without one keeps
        its own sentence. A share ``corrected_share`` of the relabelled sentences are corrections rather
        than plain instructions: those written for the object the arm acted on first in the episode,
        other than the target (where there is none, another object drawn uniformly).

        ``ground_real``: a stored transition whose sentence singles out its goal (every step of a plain
        episode, and the steps after the correction of a correction episode) is labelled with the goal
        for the attention loss; one whose correction is still pending never is.
        """
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        idx = self._draw(batch_size, rng, settings.hindsight_share)
        return sampled_batch(self.data, idx, rng, self.pool_rows, settings)

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
        if meta["format"] != _FORMAT:
            raise ValueError(f"replay buffer file format {meta['format']} is not {_FORMAT}")
        buffer = cls(
            capacity=meta["capacity"],
            obs_dim=meta["obs_dim"],
            action_dim=meta["action_dim"],
            max_objects=meta["max_objects"],
            vocabulary=Vocabulary.from_dict(meta["vocabulary"]),
            pool_rows=meta["pool_rows"],
            negations=meta["negations"],
            holdout=Holdout.from_dict(meta["holdout"]),
        )
        high = meta["high"]
        for name, array in buffer.data.items():
            array[:high] = arrays[name]
        buffer.rng.bit_generator.state = meta["rng"]
        buffer.position = meta["position"]
        buffer.high = high
        buffer.size = meta["size"]
        buffer.episodes_added = meta["episodes_added"]
        return buffer
