"""Wrappers that let general-purpose RL libraries (stable-baselines3, CleanRL) read lanro's instruction as words.

The environment observes the instruction as a ``Box`` of token ids, which a library reads as numbers: the
ids of "red" and "green" would be near or far by the accident of their order in ``word_ids.txt``. Declared as
a ``MultiDiscrete`` the same ids are categories, which stable-baselines3 one-hot encodes per word before its
default ``MultiInputPolicy`` networks see them. This module imports gymnasium alone, so a CleanRL user, or
one who never installs stable-baselines3, can use it; the stable-baselines3 features extractor that reads the
words with an embedding and a GRU is in :mod:`lanrocli.integrations.sb3`.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from lanrocli.language import Vocabulary

INSTRUCTION = "instruction"
"""The observation entry holding the goal sentence's token ids."""


class MultiDiscreteInstruction(
    gym.ObservationWrapper[dict[str, np.ndarray], np.ndarray, dict[str, np.ndarray]], gym.utils.RecordConstructorArgs
):
    """Declares the ``instruction`` entry a ``MultiDiscrete([vocabulary size] * L)``: one category per word.

    Only the space changes; the ids, their padding with 0 and every other entry pass through as they are,
    so a policy trained on the wrapped environment acts on the plain one given the same ids. The vocabulary
    is the environment's own (``LanroEnv.vocabulary``), which may be a checkpoint's rather than the
    grammar's, so the number of categories is the number of ids the environment can emit.

    It records its (empty) constructor arguments, as gymnasium's own wrappers do, so the wrapped
    environment's ``spec`` names it and ``gymnasium.make(env.spec)`` builds the same stack again, as
    ``check_env`` does.
    """

    def __init__(self, env: gym.Env[dict[str, np.ndarray], np.ndarray]) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ObservationWrapper.__init__(self, env)
        vocabulary = getattr(env.unwrapped, "vocabulary", None)
        if not isinstance(vocabulary, Vocabulary):
            raise TypeError(
                f"MultiDiscreteInstruction wraps a lanro environment (one with a vocabulary), got {env.unwrapped!r}"
            )
        space = env.observation_space
        if not isinstance(space, gym.spaces.Dict) or INSTRUCTION not in space.spaces:
            raise TypeError(f"the environment's observation space has no {INSTRUCTION!r} entry: {space}")
        self.vocabulary = vocabulary
        entries = dict(space.spaces)
        entries[INSTRUCTION] = instruction_space(vocabulary)
        self.observation_space = gym.spaces.Dict(entries)

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        return observation


def instruction_space(vocabulary: Vocabulary) -> gym.spaces.MultiDiscrete:
    """The instruction as ``vocabulary.max_length`` words, each one of the vocabulary's ids (0 is padding)."""
    return gym.spaces.MultiDiscrete(np.full(vocabulary.max_length, len(vocabulary), dtype=np.int64))
