"""The stable-baselines3 features extractor: it reads the words SB3 one-hot encoded, and SAC trains with it."""

from __future__ import annotations

from collections.abc import Iterator

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import SAC
from stable_baselines3.common.preprocessing import preprocess_obs

import lanrocli  # noqa: F401  (registers the ids)
from lanrocli.envs.env import observation_size
from lanrocli.integrations.sb3 import LanguageExtractor
from lanrocli.integrations.wrappers import MultiDiscreteInstruction
from lanrocli.language import PAD_ID, Vocabulary


@pytest.fixture(scope="module")
def env() -> Iterator[MultiDiscreteInstruction]:
    wrapped = MultiDiscreteInstruction(gym.make("lanro/Reach-v0"))
    yield wrapped
    wrapped.close()


def features(
    extractor: LanguageExtractor, space: gym.spaces.Dict, sentences: list[str], vocabulary: Vocabulary
) -> torch.Tensor:
    """The extractor's features of ``sentences`` beside one observation vector, through SB3's preprocessing."""
    obs = {
        "observation": torch.linspace(-1, 1, space["observation"].shape[0]).repeat(len(sentences), 1),
        "instruction": torch.as_tensor(vocabulary.encode_many(sentences)),
    }
    with torch.no_grad():
        return extractor(preprocess_obs(obs, space))


def test_same_sentence_same_features_one_word_changed_other_features(env: MultiDiscreteInstruction) -> None:
    torch.manual_seed(0)
    extractor = LanguageExtractor(env.observation_space)
    sentences = [
        "reach the red cube",
        "reach the red cube",
        "reach the green cube",
        "reach the red cylinder",
        "touch the red cube",
        "reach the red cube sorry the green cube",
    ]
    got = features(extractor, env.observation_space, sentences, env.vocabulary)
    assert got.shape == (len(sentences), 128 + 32) == (len(sentences), extractor.features_dim)
    torch.testing.assert_close(got[0], got[1], rtol=0, atol=0)
    for other in got[2:]:
        assert (got[0] - other).abs().max() > 1e-4
    torch.testing.assert_close(got[2:, :128], got[:1, :128].expand(4, -1), rtol=0, atol=0)  # the same observation


def test_the_one_hot_words_are_read_back_as_the_exact_ids(env: MultiDiscreteInstruction) -> None:
    torch.manual_seed(1)
    extractor = LanguageExtractor(env.observation_space, obs_size=None)
    sentences = ["reach the red cube", "contact the blue object not the red cube", "touch the cube"]
    ids = torch.as_tensor(env.vocabulary.encode_many(sentences))
    got = features(extractor, env.observation_space, sentences, env.vocabulary)
    n = observation_size(2)
    assert extractor.features_dim == n + 32
    torch.testing.assert_close(got[:, :n], torch.linspace(-1, 1, n).repeat(3, 1), rtol=0, atol=0)
    with torch.no_grad():
        torch.testing.assert_close(got[:, n:], extractor.encoder(ids), rtol=0, atol=0)


def test_an_unwrapped_instruction_is_refused_with_the_wrapper_named(env: MultiDiscreteInstruction) -> None:
    with pytest.raises(TypeError, match="MultiDiscreteInstruction"):
        LanguageExtractor(env.env.observation_space)
    other = gym.spaces.Dict({**env.observation_space.spaces, "extra": gym.spaces.Box(0, 1, (2,))})
    with pytest.raises(TypeError, match="reads a Dict of 'observation' and 'instruction'"):
        LanguageExtractor(other)
    uneven = gym.spaces.Dict(
        {"observation": env.observation_space["observation"], "instruction": gym.spaces.MultiDiscrete([61, 60])}
    )
    with pytest.raises(ValueError, match="one vocabulary"):
        LanguageExtractor(uneven)


def test_sac_trains_with_the_extractor_and_learns_word_embeddings(env: MultiDiscreteInstruction) -> None:
    model = SAC(
        "MultiInputPolicy",
        env,
        learning_starts=100,
        buffer_size=1000,
        batch_size=32,
        seed=0,
        policy_kwargs=dict(
            features_extractor_class=LanguageExtractor,
            features_extractor_kwargs=dict(embedding_size=8, language_size=8, obs_size=16),
            net_arch=[32, 32],
        ),
    )
    embedding = model.actor.features_extractor.encoder.embedding.weight
    before = embedding.detach().clone()
    model.learn(300)
    moved = (embedding.detach() - before).abs().sum(dim=1)
    assert moved[PAD_ID] == 0 and not embedding[PAD_ID].any()  # padding is never a word
    assert (moved > 0).sum() >= 4  # at least a verb, "the", a colour and a shape were learned from
    obs, _ = env.reset(seed=1)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action)
    assert isinstance(action, np.ndarray) and action.shape == (3,)
