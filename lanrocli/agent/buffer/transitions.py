"""What the replay buffer takes, keeps and hands out: an episode as it is added, the arrays it is stored in,
and a sampled batch. Apart from the buffer, so that the sampling and the learner read them without the
buffer's bookkeeping."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lanrocli.language import ObjectProps

NO_OBJECT = np.iinfo(np.uint8).max
"""Property index stored for an object slot that the episode's scene leaves empty."""

NEVER = np.iinfo(np.int32).max
"""``first_achieved`` of an object the episode never achieved the task on."""


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
    it. ``slots``: where in the buffer each transition is stored, to look up what the batch does not carry."""

    obs: np.ndarray  # float32 [B, N]
    instruction: np.ndarray  # int64 [B, L]
    action: np.ndarray  # float32 [B, A]
    reward: np.ndarray  # float32 [B]
    next_obs: np.ndarray  # float32 [B, N]
    next_instruction: np.ndarray  # int64 [B, L]
    done: np.ndarray  # bool [B]
    named: np.ndarray  # int64 [B]
    label: np.ndarray  # int64 [B]
    slots: np.ndarray  # int64 [B]

    @property
    def labelled(self) -> bool:
        """Whether any row carries a ``label``: a batch without one has no grounding loss to compute, and a
        compiled update holds a graph for each case."""
        return bool((self.label >= 0).any())

    @property
    def relabelled(self) -> np.ndarray:
        """bool [B]: which transitions got a hindsight sentence."""
        return self.named >= 0


def stored_arrays(
    obs_dim: int, action_dim: int, max_objects: int, length: int
) -> dict[str, tuple[type, tuple[int, ...]]]:
    """The buffer's arrays: name -> (dtype, shape after the slot axis), in terms of the buffer's dimensions;
    the comments say what the less obvious ones are for."""
    return {
        "obs": (np.float32, (obs_dim,)),
        "next_obs": (np.float32, (obs_dim,)),
        "action": (np.float32, (action_dim,)),
        "reward": (np.float32, ()),
        "terminated": (np.bool_, ()),
        "instruction": (np.uint8, (length,)),
        "next_instruction": (np.uint8, (length,)),
        "achieved": (np.bool_, (max_objects,)),
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
