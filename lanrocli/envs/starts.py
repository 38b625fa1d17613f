"""Where the arm starts an episode: the neutral pose, or for training a random point near the table or the
open hand around an object, drawn per episode from the stage's shares.

Corrections leave the hand low beside a wrong object or holding it, states the neutral pose seldom leads
to; these starts make them common in training. The mistake starts, which go further and have the scripted
oracle do the task on a wrong object, are the environment's (they involve the instructor)."""

from __future__ import annotations

import numpy as np

from lanrocli.envs.settings import EnvSettings
from lanrocli.sim import MAX_FINGER_WIDTH, WORKSPACE, ObjectSet, Panda

START_HEIGHT = (WORKSPACE.low[2], 0.10)
"""Heights (m) of the end effector at a random start: from the workspace floor to the neutral pose's."""

START_CLEARANCE = 0.01
"""A random start keeps every part of the arm this far (m) from every object."""

START_TRIES = 50
"""Random start positions tried before falling back to the neutral pose (nine in ten are clear)."""


def place_arm(robot: Panda, objects: ObjectSet, settings: EnvSettings, rng: np.random.Generator) -> None:
    """The neutral pose, or with probability ``object_start`` the open hand around an object, or with
    probability ``random_start`` a random point clear of the objects.

    A random arm almost never holds an object, so hindsight has no grasp to relabel
    (``benchmarks/exploration.py``); from around an object, closing and raising the hand is a matter of a
    few lucky steps. No number is drawn where both shares are 0, so such a stage's episodes are unchanged."""
    shares = settings.object_start, settings.random_start
    draw = rng.random() if any(shares) else 1.0
    if draw < shares[0] and _around_an_object(robot, objects, rng):
        return
    if shares[0] <= draw < sum(shares):
        low = (*WORKSPACE.low[:2], START_HEIGHT[0])
        high = (*WORKSPACE.high[:2], START_HEIGHT[1])
        for _ in range(START_TRIES):
            robot.reset(MAX_FINGER_WIDTH, ee_position=rng.uniform(low, high))
            if robot.clear_of(objects.body_ids, START_CLEARANCE):
                return
    robot.reset(MAX_FINGER_WIDTH)  # open, where the arm has fingers to open


def _around_an_object(robot: Panda, objects: ObjectSet, rng: np.random.Generator) -> bool:
    """The open hand with a random object between its fingers, at the object's centre height (clipped to
    the workspace); ``False`` where the fingers would cut into it (a cuboid turned across them)."""
    positions = objects.states().positions
    robot.reset(MAX_FINGER_WIDTH, ee_position=positions[int(rng.integers(len(positions)))])
    return robot.clear_of(objects.body_ids, 0.0)
