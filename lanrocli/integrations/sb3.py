"""A stable-baselines3 features extractor that reads lanro's instruction as a sentence.

SB3's default ``MultiInputPolicy`` sees the instruction, once
:class:`~lanrocli.integrations.wrappers.MultiDiscreteInstruction` declares it, as L one-hot words side by side:
enough to learn from, but the same word third and fourth in a sentence are unrelated inputs to it, and a correction's
words stand wherever its instruction ended. :class:`LanguageExtractor` reads the words in order with lanro's
own sentence encoder (a word embedding and a GRU), as lanro's agent does. This module imports
stable-baselines3; :mod:`lanrocli.integrations.wrappers` does not.
"""

from __future__ import annotations

import gymnasium as gym
import torch
from torch import nn

from lanrocli.agent.encoder import LanguageEncoder
from lanrocli.integrations.wrappers import INSTRUCTION

try:
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
except ModuleNotFoundError as error:
    raise ModuleNotFoundError(
        "lanrocli.integrations.sb3 needs stable-baselines3: pip install 'stable-baselines3>=2.4'"
    ) from error

OBSERVATION = "observation"
"""The observation entry holding the arm's and the objects' numbers."""


class LanguageExtractor(BaseFeaturesExtractor):
    """The sentence summary of a word embedding and a GRU, beside a layer (or none) over the observation vector.

    Pass it as ``policy_kwargs=dict(features_extractor_class=LanguageExtractor)`` to a ``MultiInputPolicy``
    on an environment wrapped in :class:`~lanrocli.integrations.wrappers.MultiDiscreteInstruction`. ``embedding_size``,
    ``language_size`` (the GRU's state) and ``obs_size`` mean what they mean in lanro's ``SACSettings``, and
    default to its values; ``obs_size=None`` passes the observation vector on unchanged, leaving it to the
    policy's ``net_arch``.

    SB3 one-hot encodes a ``MultiDiscrete`` entry before any features extractor sees it (``preprocess_obs``
    in the policy's ``extract_features``; an extractor cannot opt out), so the instruction arrives as
    float [B, L * V], the one-hot rows of its L words side by side. Taking each row's argmax gives back the
    exact ids, since each row holds a single 1. The encoder needs the ids, not only their embeddings (which
    multiplying the rows by the embedding's weights would give): it finds each sentence's last true word by
    its padding, its GRU's state there being the summary, so padding is never read as words
    (:class:`~lanrocli.agent.encoder.LanguageEncoder`). Keeping the instruction a ``Box`` of ids for this
    extractor instead would need a second wrapper, and leaving the extractor out would then read ids as
    numbers again.
    """

    def __init__(
        self,
        observation_space: gym.spaces.Dict,
        embedding_size: int = 32,
        language_size: int = 32,
        obs_size: int | None = 128,
    ) -> None:
        vocab_size, max_length = _instruction_shape(observation_space)
        observed = _observation_size(observation_space)
        super().__init__(observation_space, language_size + (observed if obs_size is None else obs_size))
        self.vocab_size, self.max_length = vocab_size, max_length
        self.encoder = LanguageEncoder(vocab_size, embedding_size, language_size)
        self.obs_layer: nn.Module = (
            nn.Identity() if obs_size is None else nn.Sequential(nn.Linear(observed, obs_size), nn.ReLU())
        )

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        """``observations`` as SB3's policy preprocessed them: the instruction one-hot, [B, L * V]."""
        tokens = observations[INSTRUCTION].view(-1, self.max_length, self.vocab_size).argmax(dim=2)
        return torch.cat([self.obs_layer(observations[OBSERVATION]), self.encoder(tokens)], dim=1)


def _instruction_shape(space: gym.Space) -> tuple[int, int]:
    """The vocabulary size V and sentence length L of the space's instruction, refusing any other layout."""
    if not isinstance(space, gym.spaces.Dict) or set(space.spaces) != {OBSERVATION, INSTRUCTION}:
        raise TypeError(
            f"LanguageExtractor reads a Dict of {OBSERVATION!r} and {INSTRUCTION!r}, as lanro's environments "
            f"observe, got {space}"
        )
    instruction = space[INSTRUCTION]
    if not isinstance(instruction, gym.spaces.MultiDiscrete):
        raise TypeError(
            f"LanguageExtractor reads the instruction as a MultiDiscrete, got {instruction}: wrap the "
            "environment in lanrocli.integrations.wrappers.MultiDiscreteInstruction"
        )
    nvec = instruction.nvec
    if nvec.ndim != 1 or (nvec != nvec[0]).any():
        raise ValueError(f"the instruction must be a row of words from one vocabulary, got nvec {nvec}")
    return int(nvec[0]), int(nvec.shape[0])


def _observation_size(space: gym.spaces.Dict) -> int:
    """The length of the observation vector, refusing anything but a flat Box."""
    observation = space[OBSERVATION]
    if not isinstance(observation, gym.spaces.Box) or len(observation.shape) != 1:
        raise TypeError(f"LanguageExtractor reads {OBSERVATION!r} as a flat Box, got {observation}")
    return int(observation.shape[0])
