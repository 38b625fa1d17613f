"""The instruction as a MultiDiscrete: the space a library reads, with the environment's ids unchanged."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import lanrocli  # noqa: F401  (registers the ids)
from lanrocli.envs.env import LanroEnv, observation_size
from lanrocli.integrations.wrappers import MultiDiscreteInstruction
from lanrocli.language import grammar_vocabulary
from lanrocli.language.vocabulary import agent_vocabulary


def test_the_instruction_becomes_one_category_per_word_of_the_vocabulary() -> None:
    env = MultiDiscreteInstruction(gym.make("lanro/Push-v0", objects=3, mode="colour_shape"))
    vocabulary = grammar_vocabulary()
    space = env.observation_space["instruction"]
    assert isinstance(space, gym.spaces.MultiDiscrete)
    assert space.nvec.tolist() == [len(vocabulary)] * vocabulary.max_length
    assert env.observation_space["observation"] == env.env.observation_space["observation"]
    env.close()


def test_the_categories_are_the_environments_own_vocabulary() -> None:
    vocabulary = agent_vocabulary(None, 12)  # a checkpoint's smaller vocabulary
    env = MultiDiscreteInstruction(LanroEnv("reach", vocabulary=vocabulary))
    assert env.observation_space["instruction"].nvec.tolist() == [12] * vocabulary.max_length
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    env.close()


def test_the_ids_and_the_observation_pass_through_unchanged() -> None:
    settings = dict(objects=3, mode="colour_shape", correction_rate=1.0, negations=True, max_delay=0)
    plain = gym.make("lanro/Reach-v0", **settings)
    wrapped = MultiDiscreteInstruction(gym.make("lanro/Reach-v0", **settings))
    rng = np.random.default_rng(0)
    sentences = set()
    for seed in range(3):
        expected, _ = plain.reset(seed=seed)
        got, info = wrapped.reset(seed=seed)
        for _ in range(30):
            assert got.keys() == expected.keys()
            for key in expected:
                np.testing.assert_array_equal(got[key], expected[key])
            assert got["instruction"].dtype == expected["instruction"].dtype
            np.testing.assert_array_equal(got["instruction"], wrapped.vocabulary.encode(info["instruction_text"]))
            assert wrapped.observation_space.contains(got)
            sentences.add(info["instruction_text"])
            action = rng.uniform(-1, 1, size=3).astype(np.float32)
            expected, _, done, cut, _ = plain.step(action)
            got, _, wrapped_done, wrapped_cut, info = wrapped.step(action)
            assert (wrapped_done, wrapped_cut) == (done, cut)
            if done or cut:
                break
    assert len(sentences) >= 3
    plain.close()
    wrapped.close()


def test_check_env_passes_on_the_wrapped_environment() -> None:
    env = MultiDiscreteInstruction(
        gym.make("lanro/Push-v0", correction_rate=0.5, negations=True, rare_words=True, max_delay=3).unwrapped
    )
    check_env(env, skip_render_check=True)
    env.close()


def test_the_spec_names_the_wrapper_so_gymnasium_can_make_the_stack_again() -> None:
    env = MultiDiscreteInstruction(gym.make("lanro/Grasp-v0", objects=3, max_episode_steps=70))
    again = gym.make(env.spec)
    assert isinstance(again, MultiDiscreteInstruction)
    assert again.observation_space == env.observation_space
    assert again.spec.max_episode_steps == 70 and again.unwrapped.settings.objects == 3
    env.close()
    again.close()


def test_an_environment_without_a_vocabulary_is_refused() -> None:
    env = gym.make("CartPole-v1")
    with pytest.raises(TypeError, match="wraps a lanro environment"):
        MultiDiscreteInstruction(env)
    env.close()


def test_sb3_default_policy_one_hot_encodes_each_word() -> None:
    from stable_baselines3 import SAC

    env = MultiDiscreteInstruction(gym.make("lanro/Reach-v0"))
    vocabulary = grammar_vocabulary()
    model = SAC("MultiInputPolicy", env, buffer_size=100, policy_kwargs=dict(net_arch=[8]))
    assert model.actor.features_extractor.features_dim == observation_size(2) + len(vocabulary) * vocabulary.max_length
    env.close()


def test_flattened_for_cleanrl_the_words_are_one_hot_before_the_observation_vector() -> None:
    env = gym.wrappers.FlattenObservation(MultiDiscreteInstruction(gym.make("lanro/Reach-v0")))
    vocabulary = grammar_vocabulary()
    words = len(vocabulary) * vocabulary.max_length
    assert env.observation_space.shape == (words + observation_size(2),)
    flat, info = env.reset(seed=4)
    one_hot = flat[:words].reshape(vocabulary.max_length, len(vocabulary))
    assert (one_hot.sum(axis=1) == 1).all()
    assert vocabulary.decode(one_hot.argmax(axis=1)) == info["instruction_text"]
    env.close()


def test_importing_the_wrappers_loads_neither_torch_nor_stable_baselines3() -> None:
    code = (
        "import sys, lanrocli.integrations.wrappers\n"
        "heavy = sorted(m for m in ('torch', 'stable_baselines3', 'pybullet') if m in sys.modules)\n"
        "assert not heavy, heavy\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr
