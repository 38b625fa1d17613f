"""Push: slide the named object along the table."""

from __future__ import annotations

import numpy as np

from lanrocli.tasks.base import ALIGNED, HOVER, ArmView, OracleMemory, TaskDefinition, TaskView

PUSH_DISTANCE = (0.025, 0.075)
"""Range (m) of the per-episode horizontal distance a pushed object must travel."""

PUSH_GAP = 0.035
"""Distance (m) behind an object's edge where the oracle's push starts."""

PUSH_HEIGHT = 0.02
"""Height (m) of the end effector above the table while the oracle pushes."""


class Push(TaskDefinition):
    """The object slid farther than this episode's distance, without being lifted or tipped over."""

    name = "push"
    gym_id = "lanro/Push-v0"
    verbs = ("push", "move", "shift")
    paraphrase_verbs = ("shove", "nudge")
    threshold_range = PUSH_DISTANCE

    def achieved(self, view: TaskView) -> np.ndarray:
        delta = view.positions - view.start_positions
        slid = np.linalg.norm(delta[:, :2], axis=1) > self.threshold
        return slid & (np.abs(delta[:, 2]) < view.heights)

    def oracle(self, view: ArmView, memory: OracleMemory) -> np.ndarray:
        """Above the start of the push, down behind the object, then through it along one direction, chosen
        once per object."""
        if memory.plan is None:
            memory.plan = push_direction(view)
        ee, pos = view.ee_position, view.target_position
        u = np.append(memory.plan, 0.0)
        behind = pos - u * (view.radius(view.target) + PUSH_GAP)
        if memory.phase == 0:  # travel above the start of the push
            goal = np.array([behind[0], behind[1], pos[2] + HOVER])
            if np.linalg.norm(ee[:2] - goal[:2]) < ALIGNED:
                memory.phase = 1
            return view.towards(goal)
        if memory.phase == 1:  # go down behind the object
            goal = np.array([behind[0], behind[1], PUSH_HEIGHT])
            if abs(ee[2] - PUSH_HEIGHT) < 0.01:
                memory.phase = 2
            return view.towards(goal)
        goal = pos + u * 0.03
        goal[2] = PUSH_HEIGHT
        return view.towards(goal)


def push_direction(view: ArmView) -> np.ndarray:
    """The horizontal direction whose push path and approach point stay farthest from the other objects."""
    best, best_clearance = np.array([1.0, 0.0]), -np.inf
    target, positions = view.target, view.positions
    start = positions[target, :2]
    for angle in np.linspace(0.0, 2 * np.pi, 16, endpoint=False):
        u = np.array([np.cos(angle), np.sin(angle)])
        path = start + np.outer(np.linspace(-0.09, 0.12, 12), u)
        clearance = np.inf
        for k in range(len(positions)):
            if k != target:
                gap = np.linalg.norm(path - positions[k, :2], axis=1).min() - view.radius(k)
                clearance = min(clearance, gap)
        # Prefer pushes towards the middle of the table so the object stays reachable.
        clearance -= 0.2 * max(0.0, float(np.dot(start, u)))
        if clearance > best_clearance:
            best, best_clearance = u, clearance
    return best
