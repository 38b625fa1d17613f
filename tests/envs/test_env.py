"""The gymnasium environment: its contract with agents, evaluation and the instructor."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from lanrocli.envs.env import LanroEnv, observation_size
from lanrocli.envs.policies import make_policy
from lanrocli.envs.registration import ENV_IDS
from lanrocli.language import (
    RARE_WORD_COLOURS,
    SHAPE_WORDS,
    all_corrections,
    all_instructions,
    grammar_vocabulary,
)
from lanrocli.sim import WORKSPACE
from lanrocli.sim.layout import FLOOR_HEIGHT

INFO_KEYS = {
    "is_success",
    "achieved",
    "goal_index",
    "object_positions",
    "objects",
    "instruction_text",
    "challenge",
    "correction",
    "fell",
    "asked",
    "answers",
    "referent",
    "fits",
}


def rollout(env: LanroEnv, policy_name: str, seed: int) -> list[tuple]:
    """One episode as (observation, reward, terminated, truncated, info) tuples, reset included."""
    policy = make_policy(policy_name, env.task.name)
    obs, info = env.reset(seed=seed)
    policy.reset(seed=seed)
    steps = [(obs, 0.0, False, False, info)]
    while True:
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
        steps.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            return steps


@pytest.fixture(scope="module")
def correcting_env():
    env = LanroEnv("reach", objects=3, mode="colour_shape", correction_rate=1.0, negations=True, rare_words=True)
    yield env
    env.close()


@pytest.mark.parametrize("env_id", list(ENV_IDS.values()))
def test_check_env_passes(env_id: str) -> None:
    env = gym.make(env_id, correction_rate=0.5, negations=True, rare_words=True, max_delay=3)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_spaces_and_layout() -> None:
    env = LanroEnv("lift", objects=3, mode="shape")
    obs, info = env.reset(seed=3)
    assert env.action_space.shape == (4,)
    assert obs["observation"].dtype == np.float32 and obs["observation"].shape == (observation_size(3),) == (100,)
    assert obs["instruction"].dtype == np.int64 and obs["instruction"].shape == (grammar_vocabulary().max_length,)
    assert env.observation_space.contains(obs)
    assert set(info) == INFO_KEYS
    o = obs["observation"]
    np.testing.assert_allclose(o[7:10], info["object_positions"][0], atol=1e-6)
    np.testing.assert_allclose(o[7 + 31 : 10 + 31], info["object_positions"][1], atol=1e-6)
    np.testing.assert_allclose(o[10 + 31 : 13 + 31], info["object_positions"][1] - o[:3], atol=1e-6)
    np.testing.assert_allclose(o[13 + 31 : 16 + 31], 0.0, atol=1e-6)  # nothing has moved at reset
    colour, shape = info["objects"][2].colour, info["objects"][2].shape
    one_hot = o[7 + 62 + 19 : 7 + 93]
    assert one_hot.sum() == 2 and one_hot[["red", "green", "blue"].index(colour)] == 1
    assert one_hot[9 + ["cube", "cuboid", "cylinder"].index(shape)] == 1
    assert env.max_episode_steps == 50
    assert LanroEnv("reach", correction_rate=0.5).max_episode_steps == 100
    assert LanroEnv("reach", correction_rate=0.5, max_episode_steps=7).max_episode_steps == 7
    assert LanroEnv("push").action_space.shape == (3,)


def test_same_seed_same_episodes(correcting_env: LanroEnv) -> None:
    def summary(steps: list[tuple]) -> list:
        return [
            (info["objects"], info["instruction_text"], info["correction"], info["object_positions"].round(6).tolist())
            for *_, info in steps
        ]

    for seed in range(3):
        first = summary(rollout(correcting_env, "mistaken", seed))
        second = summary(rollout(correcting_env, "mistaken", seed))
        assert first == second
    assert summary(rollout(correcting_env, "mistaken", 0)) != summary(rollout(correcting_env, "mistaken", 1))


def test_reward_and_success_follow_achieved_goal(correcting_env: LanroEnv) -> None:
    for seed in range(6):
        steps = rollout(correcting_env, "mistaken" if seed % 2 else "random", seed)
        for _, reward, terminated, truncated, info in steps[1:]:
            achieved = bool(info["achieved"][info["goal_index"]])
            assert info["is_success"] == achieved == terminated
            assert reward == (0.0 if achieved else -1.0)
            assert not (terminated and truncated)
        assert steps[-1][2] or len(steps) - 1 == correcting_env.max_episode_steps


def test_corrections_reach_the_observation_on_the_step_they_are_spoken(correcting_env: LanroEnv) -> None:
    vocab = grammar_vocabulary()
    instructions = {t for task in ("reach",) for t, _ in all_instructions(task, rare=True)}
    corrections = {t for t, _ in all_corrections(negations=True)}
    kinds, wrong_first_objects, negations = set(), set(), set()
    for seed in range(40):
        steps = rollout(correcting_env, "mistaken", seed)
        spoken_step = None
        for t, (obs, _, terminated, _, info) in enumerate(steps):
            assert vocab.decode(obs["instruction"]) == info["instruction_text"]
            correction = info["correction"]
            if correction is not None and spoken_step is None:
                spoken_step = t
                assert correction["spoken_at"] == t
                assert not terminated, "the episode must not end on the step a correction is spoken"
                assert info["instruction_text"].endswith(" " + correction["text"])
                assert correction["text"] in corrections
                assert info["instruction_text"][: -len(correction["text"]) - 1] in instructions
                kinds.add(correction["kind"])
                negations.add(correction["negation"])
                touched = np.flatnonzero(info["achieved"])
                wrong_first_objects.update(int(k) for k in touched if k != info["goal_index"])
        assert spoken_step is not None
    assert kinds == {"ambiguity", "common_ground", "instruction_correction", "wrong_object"}
    assert negations == {True, False}
    assert 0 in wrong_first_objects, "work on the object with index 0 must be noticed"


@pytest.mark.parametrize("n_objects", [2, 3])
def test_common_ground_episodes_need_their_rare_colour_word(n_objects: int) -> None:
    env = LanroEnv(
        "reach", objects=n_objects, mode="colour_shape", correction_rate=1.0, rare_words=True, kinds=["common_ground"]
    )
    shape_of = {word: shape for shape, words in SHAPE_WORDS.items() for word in words}
    for seed in range(100):
        _, info = env.reset(seed=seed)
        rare, noun = info["instruction_text"].split()[-2:]
        assert rare in RARE_WORD_COLOURS
        shape = shape_of.get(noun)  # None for "object"
        without_colour = [k for k, o in enumerate(info["objects"]) if shape is None or o.shape == shape]
        assert info["goal_index"] in without_colour and len(without_colour) >= 2, info
    env.close()


def test_delayed_corrections_arrive_within_max_delay() -> None:
    env = LanroEnv("push", objects=2, correction_rate=1.0, max_delay=10, kinds=["wrong_object"])
    waits = set()
    for seed in range(12):
        info = rollout(env, "mistaken", seed)[-1][-1]
        correction = info["correction"]
        assert correction is not None
        wait = correction["spoken_at"] - correction["triggered_at"]
        assert 0 <= wait <= 10
        waits.add(wait)
    assert len(waits) > 1
    env.close()


def test_two_environments_do_not_interfere() -> None:
    alone = LanroEnv("push", objects=2)
    reference = [s[-1]["object_positions"].tolist() for s in rollout(alone, "oracle", 5)]
    alone.close()
    first, second = LanroEnv("push", objects=2), LanroEnv("push", objects=3)
    obs1, info1 = first.reset(seed=5)
    second.reset(seed=9)
    policy = make_policy("oracle", "push")
    policy.reset(seed=5)
    interleaved = [info1["object_positions"].tolist()]
    for _ in range(len(reference) - 1):
        obs1, _, _, _, info1 = first.step(policy.act(obs1, info1))
        second.step(second.action_space.sample())
        interleaved.append(info1["object_positions"].tolist())
    assert interleaved == reference
    first.close()
    second.close()


@pytest.mark.parametrize(
    "kwargs, setting",
    [
        ({"objects": 9}, "objects"),
        ({"mode": "weird"}, "mode"),
        ({"correction_rate": 1.5}, "correction_rate"),
        ({"task": "fly"}, "task"),
        ({"max_delay": -2}, "max_delay"),
        ({"kinds": ["gossip"]}, "kinds"),
        ({"random_start": -0.1}, "random_start"),
        ({"mistake_start": 1.2}, "mistake_start"),
        ({"question_penalty": -0.5}, "question_penalty"),
        ({"question_steps": -1}, "question_steps"),
        ({"questions": 1, "question_steps": 0}, "free"),
    ],
)
def test_bad_settings_raise_clear_errors(kwargs: dict, setting: str) -> None:
    with pytest.raises(ValueError, match=setting):
        LanroEnv(**kwargs)


@pytest.mark.parametrize("task, threshold", [("reach", 0.95), ("push", 0.9), ("grasp", 0.85), ("lift", 0.8)])
def test_oracle_solves_the_task(task: str, threshold: float) -> None:
    env = LanroEnv(task, objects=2, mode="colour_shape")
    successes = [rollout(env, "oracle", seed)[-1][-1]["is_success"] for seed in range(12)]
    assert np.mean(successes) >= threshold
    env.close()


def test_random_policy_rarely_succeeds() -> None:
    env = LanroEnv("lift", objects=2)
    successes = [rollout(env, "random", seed)[-1][-1]["is_success"] for seed in range(5)]
    assert np.mean(successes) < 0.5
    env.close()


def test_render_returns_a_captioned_image() -> None:
    env = LanroEnv("reach", render_mode="rgb_array")
    env.reset(seed=0)
    image = env.render()
    assert image is not None and image.dtype == np.uint8 and image.shape == (360, 480, 3)
    assert image[:20].mean() < image[100:].mean()  # the dark caption band
    env.close()


@pytest.mark.parametrize("task", ["push", "lift"])
def test_an_environment_that_renders_plays_the_episodes_of_one_that_does_not(task: str) -> None:
    """Only a rendering environment loads the arm's visual meshes; every number of its episodes must be the same."""

    def episodes(render_mode: str | None) -> list[tuple]:
        env = LanroEnv(task, objects=3, mode="colour_shape", correction_rate=1.0, render_mode=render_mode)
        try:
            return [
                (obs["observation"].tolist(), obs["instruction"].tolist(), reward, info["object_positions"].tolist())
                for seed in range(2)
                for obs, reward, *_, info in rollout(env, "mistaken", seed)
            ]
        finally:
            env.close()

    assert episodes("rgb_array") == episodes(None)


def test_object_slots_pad_the_observation_with_zeros() -> None:
    env = LanroEnv("reach", objects=2, object_slots=3)
    obs, _ = env.reset(seed=4)
    assert env.observation_space["observation"].shape == (observation_size(3),)
    assert obs["observation"].shape == (observation_size(3),)
    assert np.all(obs["observation"][observation_size(2) :] == 0.0)
    plain = LanroEnv("reach", objects=2)
    np.testing.assert_array_equal(plain.reset(seed=4)[0]["observation"], obs["observation"][: observation_size(2)])
    env.close()
    plain.close()
    with pytest.raises(ValueError, match="object_slots"):
        LanroEnv("reach", objects=3, object_slots=2)


def test_random_starts_put_the_hand_near_the_table_clear_of_the_objects() -> None:
    env = LanroEnv("reach", objects=3, mode="colour_shape", random_start=1.0)
    starts = []
    for seed in range(40):
        obs, info = env.reset(seed=seed)
        starts.append(obs["observation"][:3].copy())
        placed = info["object_positions"]
        for _ in range(2):
            obs, _, _, _, info = env.step(np.zeros(3))
        assert not env.robot.contacts(env.objects.body_ids).robot.any(), f"seed {seed}: the arm starts on an object"
        np.testing.assert_allclose(info["object_positions"], placed, atol=1e-3)
    starts = np.array(starts)
    assert np.all(starts >= np.array(WORKSPACE.low) - 1e-3) and np.all(starts[:, 2] <= 0.101)
    assert starts[:, 2].min() < 0.03  # some start low beside the objects, where corrections leave the hand
    assert np.std(starts[:, 0]) > 0.05 and np.std(starts[:, 1]) > 0.05
    again = LanroEnv("reach", objects=3, mode="colour_shape", random_start=1.0)
    np.testing.assert_array_equal(again.reset(seed=7)[0]["observation"], env.reset(seed=7)[0]["observation"])
    env.close()
    again.close()


def test_random_start_share_is_respected_and_zero_changes_nothing() -> None:
    half = LanroEnv("reach", random_start=0.5)
    neutral = [bool(np.allclose(half.reset(seed=s)[0]["observation"][:3], (0, 0, 0.10), atol=2e-3)) for s in range(60)]
    assert 18 <= sum(neutral) <= 42
    plain, zero = LanroEnv("reach", correction_rate=0.5), LanroEnv("reach", correction_rate=0.5, random_start=0.0)
    for seed in range(3):
        first, info = plain.reset(seed=seed)
        second, info_zero = zero.reset(seed=seed)
        np.testing.assert_array_equal(first["observation"], second["observation"])
        assert info["instruction_text"] == info_zero["instruction_text"]
    for env in (half, plain, zero):
        env.close()


def test_object_starts_open_the_hand_around_an_object_without_touching_it() -> None:
    env = LanroEnv("grasp", objects=3, mode="colour_shape", object_start=1.0)
    chosen = set()
    for seed in range(30):
        obs, info = env.reset(seed=seed)
        offsets = np.linalg.norm(info["object_positions"] - obs["observation"][:3], axis=1)
        assert offsets.min() < 0.005, f"seed {seed}: the hand is {offsets.min():.3f} m from the nearest object"
        chosen.add(int(offsets.argmin()))
        assert obs["observation"][6] == pytest.approx(0.08, abs=1e-3)  # fingers open
        assert not env.robot.contacts(env.objects.body_ids).robot.any(), f"seed {seed}: the fingers cut in"
    assert chosen == {0, 1, 2}
    env.close()


def test_from_an_object_start_closing_and_raising_the_hand_grasps() -> None:
    env = LanroEnv("grasp", objects=2, object_start=1.0)
    for seed in range(3):
        _, info = env.reset(seed=seed)
        for _ in range(8):
            _, _, _, _, info = env.step(np.array([0.0, 0.0, 0.0, -1.0]))
        for _ in range(2):
            _, _, _, _, info = env.step(np.array([0.0, 0.0, 1.0, -1.0]))
        assert info["achieved"].any(), f"seed {seed}: closing and raising the hand held nothing"
    env.close()


@pytest.mark.parametrize("task", ["reach", "push", "grasp", "lift"])
def test_a_mistake_start_begins_with_the_task_done_on_a_wrong_object_and_the_instructor_corrects_it(task: str) -> None:
    env = LanroEnv(task, objects=3, mode="colour_shape", correction_rate=1.0, mistake_start=1.0)
    corrected_at = []
    for seed in range(12):
        obs, info = env.reset(seed=seed)
        wrong = [k for k in np.flatnonzero(info["achieved"]) if k != info["goal_index"]]
        assert len(wrong) == 1 and not info["is_success"], f"seed {seed}: achieved {info['achieved']}"
        assert info["correction"] is None and info["instruction_text"] == env.instructor.instruction_text
        _, _, _, _, info = env.step(np.append(np.zeros(3), [-1.0] * (env.action_space.shape[0] - 3)))
        corrected_at.append(None if info["correction"] is None else info["correction"]["spoken_at"])
    assert corrected_at.count(1) >= 10  # max_delay 0: spoken at the first step, on the object the start acted on
    env.close()


def test_a_mistake_start_share_is_respected_and_zero_changes_nothing() -> None:
    half = LanroEnv("push", mistake_start=0.5)
    mistakes = [bool(half.reset(seed=s)[1]["achieved"].any()) for s in range(40)]
    assert 10 <= sum(mistakes) <= 30
    plain, zero = LanroEnv("push", correction_rate=0.5), LanroEnv("push", correction_rate=0.5, mistake_start=0.0)
    for seed in range(3):
        np.testing.assert_array_equal(plain.reset(seed=seed)[0]["observation"], zero.reset(seed=seed)[0]["observation"])
    for env in (half, plain, zero):
        env.close()


def test_start_shares_split_the_episodes_and_need_a_gripper() -> None:
    env = LanroEnv("lift", object_start=0.3, random_start=0.3)
    kinds = []
    for seed in range(90):
        obs, info = env.reset(seed=seed)
        ee = obs["observation"][:3]
        if np.allclose(ee, (0, 0, 0.10), atol=2e-3):
            kinds.append("neutral")
        elif np.linalg.norm(info["object_positions"] - ee, axis=1).min() < 0.005:
            kinds.append("object")
        else:
            kinds.append("random")
    for kind in ("neutral", "object", "random"):
        assert 15 <= kinds.count(kind) <= 45, (kind, kinds.count(kind))
    env.close()
    with pytest.raises(ValueError, match="object_start is 0.5, but it needs a task with a gripper"):
        LanroEnv("push", object_start=0.5)


def test_the_goal_falling_off_the_table_truncates_the_episode_another_object_lands_on_the_floor() -> None:
    env = LanroEnv("push", objects=2)
    _, info = env.reset(seed=0)
    goal, other = info["goal_index"], 1 - info["goal_index"]
    _, _, terminated, truncated, info = env.step(np.zeros(3))
    assert not (terminated or truncated or info["fell"])

    def drop(index: int) -> None:
        body = env.objects.body_ids[index]
        env.world.client.resetBasePositionAndOrientation(body, (0.5, 0.0, -0.1), (0.0, 0.0, 0.0, 1.0))
        env.world.invalidate()

    drop(other)
    for _ in range(40):  # about a second and a half: long enough to reach the floor and settle
        _, reward, terminated, truncated, info = env.step(np.zeros(3))
        assert not (terminated or truncated or info["fell"]) and reward == -1.0
    assert abs(info["object_positions"][other, 2] - FLOOR_HEIGHT) < 0.05  # at rest on the floor, not falling on
    drop(goal)
    _, reward, terminated, truncated, info = env.step(np.zeros(3))
    assert truncated and not terminated and reward == -1.0 and info["object_positions"][goal, 2] < -0.1
    assert info["fell"]  # the learner tells this end from the time limit's
    env.close()


def test_chains_of_corrections_get_room_in_the_sentence() -> None:
    env = LanroEnv("push", objects=3, mode="colour_shape", correction_rate=1.0, negations=True, max_corrections=2)
    assert env.vocabulary.max_length == 16 == env.observation_space["instruction"].shape[0]
    env.close()
    with pytest.raises(ValueError, match="encodes at most 10"):
        LanroEnv("push", objects=3, max_corrections=2, vocabulary=grammar_vocabulary())


@pytest.mark.parametrize("steps, penalty", [(3, 0.0), (0, 0.25), (1, 0.5)])
def test_a_question_costs_what_the_settings_say(steps: int, penalty: float) -> None:
    """A question holds the arm for ``question_steps`` steps of the episode's clock and takes
    ``question_penalty`` off the reward; the answer is in the observation returned, and once the episode's
    questions are spent, the last action number is ignored and the arm moves."""
    env = LanroEnv(
        "reach",
        objects=2,
        correction_rate=1.0,
        max_corrections=2,
        questions=1,
        question_steps=steps,
        question_penalty=penalty,
        max_episode_steps=20,
    )
    try:
        assert env.action_space.shape == (4,)
        observation, info = env.reset(seed=2)
        hand = observation["observation"][:3].copy()
        asking = np.array([1.0, 0.0, 0.0, 1.0])
        observation, reward, _, _, info = env.step(asking)
        assert info["asked"] and reward == -1.0 - penalty and env._steps == steps
        assert np.linalg.norm(observation["instruction"]) > 0 and info["instruction_text"].endswith(
            info["answers"][0]["text"]
        )
        assert info["answers"][0]["asked_at"] == 0
        assert np.allclose(observation["observation"][:3], hand, atol=0.01)  # the arm held still
        observation, reward, _, _, info = env.step(asking)
        assert not info["asked"] and reward == -1.0 and env._steps == steps + 1 and len(info["answers"]) == 1
        assert observation["observation"][0] > hand[0] + 0.01  # the action's dx moved the hand this time
    finally:
        env.close()


def test_without_questions_actions_keep_their_size() -> None:
    env = LanroEnv("push")
    try:
        assert env.action_space.shape == (3,)
        _, info = env.reset(seed=0)
        assert info["answers"] == [] and not info["asked"]
    finally:
        env.close()


class AskingLate:
    """The mistaken policy, asking at every step: its question may come while a correction waits to be
    spoken, and the question's steps may bring that correction."""

    def __init__(self) -> None:
        self.policy = make_policy("mistaken", "reach")

    def reset(self, seed: int | None = None) -> None:
        self.policy.reset(seed)

    def act(self, observation: dict[str, np.ndarray], info: dict) -> np.ndarray:
        return np.append(self.policy.act(observation, info), 1.0)


def test_a_question_at_every_step_is_answered_once_and_corrections_still_follow() -> None:
    env = LanroEnv(
        "reach",
        objects=3,
        mode="colour_shape",
        correction_rate=1.0,
        max_corrections=2,
        max_delay=10,
        questions=1,
        question_steps=3,
    )
    policy = AskingLate()
    corrected = 0
    try:
        for seed in range(12):
            observation, info = env.reset(seed=seed)
            policy.reset(seed)
            done = False
            while not done:
                observation, _, terminated, truncated, info = env.step(policy.act(observation, info))
                done = terminated or truncated
            (answer,) = info["answers"]  # one question an episode, asked at the first step
            assert answer["asked_at"] == 0 and answer["text"] in info["instruction_text"]
            assert len(info["instruction_text"].split()) <= env.vocabulary.max_length
            corrected += info["correction"] is not None
        assert corrected >= 6  # the mistaken policy's mistakes are corrected after the answer
    finally:
        env.close()
