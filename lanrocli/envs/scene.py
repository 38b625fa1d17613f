"""Which objects lie on the table, which one is the goal, and where: sampled per episode.

The paper's rule: every non-goal object shares at most one property with the goal, so a sentence that
names both of the goal's properties always identifies it, and every correction can name a unique object.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from lanrocli.language import COLOURS, SHAPES, ObjectProps


class Mode(str, Enum):
    """Which properties vary between objects."""

    COLOR = "color"  # cubes in the 9 colours
    SHAPE = "shape"  # the 3 shapes in 3 colours
    COLOR_SHAPE = "color_shape"  # the 3 shapes in the 9 colours


SHAPE_MODE_COLOURS: tuple[str, ...] = ("red", "green", "blue")


def mode_catalogue(mode: Mode) -> tuple[ObjectProps, ...]:
    """Every object a mode may put on the table."""
    if mode is Mode.COLOR:
        return tuple(ObjectProps(c, "cube") for c in COLOURS)
    colours = SHAPE_MODE_COLOURS if mode is Mode.SHAPE else COLOURS
    return tuple(ObjectProps(c, s) for c in colours for s in SHAPES)


@dataclass(frozen=True)
class Scene:
    """One episode's objects (in observation order), the goal among them and their start positions (x, y)."""

    objects: tuple[ObjectProps, ...]
    goal_index: int
    positions: np.ndarray  # float64 (n, 2), metres on the table top

    @property
    def goal(self) -> ObjectProps:
        return self.objects[self.goal_index]

    def others(self, index: int) -> list[ObjectProps]:
        return [o for i, o in enumerate(self.objects) if i != index]


def sample_objects(
    rng: np.random.Generator, mode: Mode, n_objects: int, need_shared: bool = False
) -> tuple[tuple[ObjectProps, ...], int]:
    """Distinct objects in observation order and the goal's index, obeying the at-most-one-shared-property rule.

    ``need_shared`` asks for at least one non-goal object that shares a property with the goal, which an
    ambiguous instruction needs. It is always possible: in every mode some object shares exactly one
    property with any goal.
    """
    catalogue = mode_catalogue(mode)
    goal = catalogue[int(rng.integers(len(catalogue)))]
    allowed = [o for o in catalogue if o.shared_properties(goal) <= 1]
    others = [allowed[i] for i in rng.choice(len(allowed), size=n_objects - 1, replace=False)]
    if need_shared and not any(o.shared_properties(goal) == 1 for o in others):
        shared = [o for o in allowed if o.shared_properties(goal) == 1 and o not in others]
        others[int(rng.integers(len(others)))] = shared[int(rng.integers(len(shared)))]
    goal_index = int(rng.integers(n_objects))
    objects = others[:goal_index] + [goal] + others[goal_index:]
    return tuple(objects), goal_index


def sample_positions(
    rng: np.random.Generator, n: int, low: np.ndarray, high: np.ndarray, min_distance: float, max_tries: int = 1000
) -> np.ndarray:
    """``n`` points in the rectangle [low, high] no two closer than ``min_distance`` (rejection sampling)."""
    for _ in range(max_tries):
        points = rng.uniform(low, high, size=(n, 2))
        gaps = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
        if n < 2 or gaps[np.triu_indices(n, 1)].min() >= min_distance:
            return points
    raise RuntimeError(f"could not place {n} objects {min_distance} m apart in the object area after {max_tries} tries")


def sample_scene(
    rng: np.random.Generator,
    mode: Mode,
    n_objects: int,
    area_low: np.ndarray,
    area_high: np.ndarray,
    min_distance: float,
    need_shared: bool = False,
) -> Scene:
    objects, goal_index = sample_objects(rng, mode, n_objects, need_shared)
    positions = sample_positions(rng, n_objects, area_low, area_high, min_distance)
    return Scene(objects, goal_index, positions)
