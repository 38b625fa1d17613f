"""Lift: hold the named object and raise it."""

from __future__ import annotations

import numpy as np

from lanrocli.tasks.base import TaskView
from lanrocli.tasks.grasp import Grasp, held

LIFT_HEIGHT = (0.0, 0.10)
"""Range (m) of the per-episode height a lifted object must be raised above its start."""


class Lift(Grasp):
    """Held, and raised above this episode's height; the oracle's grasp already carries the object high."""

    name = "lift"
    gym_id = "lanro/Lift-v0"
    verbs = ("lift", "raise", "hoist")
    paraphrase_verbs = ("elevate", "heave")
    threshold_range = LIFT_HEIGHT

    def achieved(self, view: TaskView) -> np.ndarray:
        raised = view.positions[:, 2] - view.start_positions[:, 2]
        return held(view) & (raised > self.threshold)
