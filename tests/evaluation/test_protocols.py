"""The benchmark's episodes are fixed by its version: the first episodes of every protocol are held here,
and a change to them fails until the version moves with them."""

from __future__ import annotations

import hashlib
import json

import pytest

from lanrocli.core.choices import Split
from lanrocli.envs.policies import make_policy
from lanrocli.evaluation.benchmark import protocol_env
from lanrocli.evaluation.protocols import PROTOCOL_VERSION, PROTOCOLS, find_protocol, first_seed

EPISODES = {
    1: "829d56c9e1f00372",
}
"""Each version's digest of :func:`first_episodes`: a version keeps its digest for good, so a change to the
episodes needs a new version (and a line here), never a new digest under an old one."""


def first_episodes(task: str, episodes: int = 2) -> list[dict]:
    """Each protocol's first episodes on ``task``: the scene, the goal, the instruction, and the sentence
    at the end of the episode played by the policy that first acts on a wrong object (its corrections)."""
    played = []
    for name, chosen in PROTOCOLS.items():
        env = protocol_env(task, chosen)()
        policy = make_policy("mistaken", task)
        try:
            for i in range(episodes):
                seed = first_seed(task, chosen) + i
                observation, info = env.reset(seed=seed)
                policy.reset(seed=seed)
                scene = {
                    "protocol": name,
                    "objects": [f"{o.colour} {o.shape}" for o in info["objects"]],
                    "positions": [round(float(x), 4) for x in info["object_positions"].ravel()],
                    "goal": int(info["goal_index"]),
                    "instruction": info["instruction_text"],
                }
                done = False
                while not done:
                    observation, _, terminated, truncated, info = env.step(policy.act(observation, info))
                    done = terminated or truncated
                played.append(scene | {"spoken": info["instruction_text"]})
        finally:
            env.close()
    return played


def digest(episodes: list[dict]) -> str:
    return hashlib.sha256(json.dumps(episodes, sort_keys=True).encode()).hexdigest()[:16]


def test_the_first_episodes_of_every_protocol_are_those_of_its_version() -> None:
    episodes = first_episodes("push")
    found = digest(episodes)
    assert found == EPISODES.get(PROTOCOL_VERSION), (
        f"the benchmark's episodes changed (digest {found}): raise PROTOCOL_VERSION and add "
        f"{{{PROTOCOL_VERSION + 1}: {found!r}}} to EPISODES. The first episodes now: {json.dumps(episodes[:3])}"
    )
    assert len(set(EPISODES.values())) == len(EPISODES)


def test_every_protocol_plays_episodes_of_its_own() -> None:
    seeds = {first_seed(task, chosen) for task in ("push", "reach") for chosen in PROTOCOLS.values()}
    assert len(seeds) == 2 * len(PROTOCOLS)
    assert {chosen.split for chosen in PROTOCOLS.values()} >= set(Split)


def test_an_unknown_protocol_or_task_is_refused_with_the_choices() -> None:
    with pytest.raises(ValueError, match="correction_test"):
        find_protocol("corrections")
    with pytest.raises(ValueError, match="push"):
        protocol_env("quick", PROTOCOLS["test"])
