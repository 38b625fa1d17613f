"""Eq. 1 of the paper: the reward is 0 when the task holds for the goal object and -1 otherwise.

The environment pays it, hindsight relabelling recomputes it for new goals, the critic bounds its targets by
the returns it allows, and evaluation sums it: all of them read it here.
"""

SUCCESS_REWARD = 0.0
FAILURE_REWARD = -1.0


def reward(success: bool) -> float:
    return SUCCESS_REWARD if success else FAILURE_REWARD
