"""The task conditions C_T, read from hand-made views of the table (no physics)."""

from __future__ import annotations

import numpy as np
import pytest

from lanrocli.tasks import Grasp, Lift, Push, Reach, TaskView, make_task
from lanrocli.tasks.grasp import OFF_TABLE
from lanrocli.tasks.reach import REACH_STILL

STARTS = np.array([[0.0, 0.0, 0.02], [0.1, 0.0, 0.02], [0.0, 0.1, 0.02]])


def view(
    moved: np.ndarray | None = None,
    left: tuple[bool, ...] = (False, False, False),
    right: tuple[bool, ...] = (False, False, False),
    ee: tuple[float, float, float] = (0.0, 0.0, 0.2),
) -> TaskView:
    moved = np.zeros_like(STARTS) if moved is None else moved
    return TaskView(
        left_finger=np.array(left),
        right_finger=np.array(right),
        positions=STARTS + moved,
        start_positions=STARTS,
        heights=np.full(3, 0.04),
        ee_position=np.array(ee),
    )


def test_reach_is_a_finger_touch_on_an_object_still_in_place() -> None:
    reach = Reach()
    assert reach.achieved(view(left=(True, False, False))).tolist() == [True, False, False]
    assert reach.achieved(view(right=(False, False, True))).tolist() == [False, False, True]
    assert not reach.achieved(view()).any()


def test_reach_fails_on_an_object_knocked_farther_than_the_limit() -> None:
    moved = np.zeros_like(STARTS)
    moved[0, 0] = REACH_STILL * 0.9
    assert Reach().achieved(view(moved, left=(True, False, False)))[0]
    moved[0, 0] = REACH_STILL * 1.1
    assert not Reach().achieved(view(moved, left=(True, False, False)))[0]


def test_reach_on_one_object_ignores_another_knocked_away() -> None:
    """C_T is per object: leaving a wrong object by dragging it must not make the goal unreachable."""
    moved = np.zeros_like(STARTS)
    moved[1] = [0.2, 0.0, 0.0]
    achieved = Reach().achieved(view(moved, left=(True, True, False)))
    assert achieved.tolist() == [True, False, False]


def test_push_needs_the_episode_distance_without_lifting() -> None:
    push = Push()
    push.reset(np.random.default_rng(0))
    moved = np.zeros_like(STARTS)
    moved[0, 1] = push.threshold * 1.01
    moved[1, 0] = push.threshold * 0.99
    moved[2, 0] = push.threshold * 1.01
    moved[2, 2] = 0.05  # lifted off the table by more than its height
    assert push.achieved(view(moved)).tolist() == [True, False, False]


def test_grasp_and_lift_need_both_fingers_and_the_object_raised() -> None:
    raised = np.zeros_like(STARTS)
    raised[0, 2] = OFF_TABLE * 1.5
    both = view(raised, left=(True, False, False), right=(True, False, False), ee=(0.0, 0.0, 0.04))
    one = view(raised, left=(True, False, False), ee=(0.0, 0.0, 0.04))
    far = view(raised, left=(True, False, False), right=(True, False, False), ee=(0.1, 0.0, 0.04))
    assert Grasp().achieved(both).tolist() == [True, False, False]
    assert not Grasp().achieved(one).any()
    assert not Grasp().achieved(far).any()
    lift = Lift()
    lift.threshold = OFF_TABLE * 2
    assert not lift.achieved(both).any()
    lift.threshold = OFF_TABLE
    assert lift.achieved(both).tolist() == [True, False, False]


def test_unknown_task_names_the_choices() -> None:
    with pytest.raises(ValueError, match="grasp"):
        make_task("wave")
