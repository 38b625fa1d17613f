"""Synthetic episodes shaped like the environment's, for buffer and agent tests."""

from __future__ import annotations

import numpy as np

from lanrocli.agent.buffer.transitions import EpisodeData
from lanrocli.language import COLOURS, SHAPES, TASK_VERBS, ObjectProps, grammar_vocabulary, instruction, object_phrases

VOCAB = grammar_vocabulary()
OBS_DIM = 8
ACTION_DIM = 3


def random_episode(
    rng: np.random.Generator, episode_id: int, task: str = "push", max_steps: int = 30, steps: int | None = None
) -> EpisodeData:
    """An episode whose observations carry (episode_id, step) in their first two entries.

    Objects are random (twins included); each object may be achieved from some step on, and the episode
    ends at the first step that achieves the goal, as success ends the real ones. With ``steps`` given the
    episode has exactly that many (the goal is then achieved, if at all, at the last step only).
    """
    n = int(rng.integers(1, 4))
    objects = [ObjectProps(COLOURS[rng.integers(len(COLOURS))], SHAPES[rng.integers(len(SHAPES))]) for _ in range(n)]
    exact = steps is not None
    steps = steps if steps is not None else int(rng.integers(1, max_steps + 1))
    achieved = np.zeros((steps, n), dtype=bool)
    for k in range(n):
        if rng.random() < 0.4:
            achieved[int(rng.integers(steps)) :, k] = True
    goal = int(rng.integers(n))
    if exact:
        achieved[:-1, goal] = False
    elif achieved[:, goal].any():
        steps = int(np.argmax(achieved[:, goal])) + 1
        achieved = achieved[:steps]
    terminated = np.zeros(steps, dtype=bool)
    terminated[-1] = achieved[-1, goal]
    phrases = object_phrases(objects[goal])
    text = instruction(TASK_VERBS[task][0], phrases[int(rng.integers(len(phrases)))])
    instructions = np.tile(VOCAB.encode(text), (steps, 1))
    obs = rng.normal(size=(steps + 1, OBS_DIM)).astype(np.float32)
    obs[:, 0] = episode_id
    obs[:, 1] = np.arange(steps + 1)
    return EpisodeData(
        observations=obs[:-1],
        next_observations=obs[1:],
        instructions=instructions,
        next_instructions=instructions.copy(),
        actions=rng.uniform(-1, 1, size=(steps, ACTION_DIM)).astype(np.float32),
        rewards=np.where(achieved[:, goal], 0.0, -1.0).astype(np.float32),
        terminated=terminated,
        achieved=achieved,
        goal_index=goal,
        objects=tuple(objects),
        task=task,
    )
