"""Which objects lie on the table, which one is the goal, and where: sampled per episode.

The paper's rule: every non-goal object shares at most one property with the goal, so a sentence that
names both of the goal's properties always identifies it, and every correction can name a unique object.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lanrocli.core.choices import Mode, Split
from lanrocli.language import COLOURS, SHAPES, ObjectProps
from lanrocli.language.holdout import NOTHING_HELD_OUT, Holdout

SHAPE_MODE_COLOURS: tuple[str, ...] = ("red", "green", "blue")


def mode_catalogue(mode: Mode) -> tuple[ObjectProps, ...]:
    """Every object a mode may put on the table."""
    if mode is Mode.COLOUR:
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
    rng: np.random.Generator,
    mode: Mode,
    n_objects: int,
    need_shared: bool = False,
    need_same_shape: bool = False,
    holdout: Holdout = NOTHING_HELD_OUT,
    split: Split | None = None,
) -> tuple[tuple[ObjectProps, ...], int]:
    """Distinct objects in observation order and the goal's index, obeying the at-most-one-shared-property rule.

    ``need_shared`` asks for at least one non-goal object that shares a property with the goal, which an
    ambiguous instruction needs. It is always possible: in every mode some object shares exactly one
    property with any goal.

    ``need_same_shape`` asks for at least one non-goal object of the goal's shape (and so, by the rule,
    of another colour), which a common-ground instruction needs: "the azure brick" tests whether the
    agent has learnt the rare word only if "the brick" alone would leave a choice. The other rare form,
    "the azure object", names no shape and leaves every object a candidate without the colour word. In
    ``colour`` mode every object is a cube, so any scene qualifies; in the other modes the goal's shape
    comes in at least three colours, so such an object always exists. Each request is met by swapping
    one drawn object for a qualifying one: two more draws from ``rng`` at most, so the draw stays cheap
    and episodes stay a function of the seed.

    ``holdout`` and ``split`` narrow the catalogue: no held-out pair is drawn, except as the goal of the
    ``pairs`` split, whose goal is always one (:func:`check_scenes` makes sure every draw can succeed).
    """
    catalogue = mode_catalogue(mode)
    goals = holdout.goals(catalogue, split)
    goal = goals[int(rng.integers(len(goals)))]
    allowed = [o for o in holdout.others(catalogue) if o.shared_properties(goal) <= 1]
    others = [allowed[i] for i in rng.choice(len(allowed), size=n_objects - 1, replace=False)]
    if need_shared and not any(o.shared_properties(goal) == 1 for o in others):
        _swap_in(rng, others, [o for o in allowed if o.shared_properties(goal) == 1])
    if need_same_shape and not any(o.shape == goal.shape for o in others):
        _swap_in(rng, others, [o for o in allowed if o.shape == goal.shape])
    goal_index = int(rng.integers(n_objects))
    objects = others[:goal_index] + [goal] + others[goal_index:]
    return tuple(objects), goal_index


def check_scenes(mode: Mode, n_objects: int, holdout: Holdout, split: Split | None = None) -> None:
    """Raise a ValueError saying why, where ``holdout`` leaves a scene of ``mode`` without a valid goal: no
    goal left to draw, or a goal without the other objects, or the object sharing a property with it, or
    the object of its shape, that its episodes may need."""
    catalogue = mode_catalogue(mode)
    goals = holdout.goals(catalogue, split)
    where = f"{mode.value} scenes of {n_objects} objects" + (f" in the {split.value} split" if split else "")
    if not goals:
        held = "holds out every object they may have" if split is None else "holds out none of their objects"
        raise ValueError(f"it {held}, so {where} have no goal")
    others = holdout.others(catalogue)
    for goal in goals:
        allowed = [o for o in others if o.shared_properties(goal) <= 1]
        needs = {
            f"{n_objects - 1} other objects": len(allowed) >= n_objects - 1,
            "an object sharing a property with it (ambiguity)": any(o.shared_properties(goal) == 1 for o in allowed),
            "an object of its shape (common ground)": any(o.shape == goal.shape for o in allowed),
        }
        missing = [need for need, met in needs.items() if not met]
        if missing:
            raise ValueError(
                f"it leaves {where} with goal {goal.colour} {goal.shape} and no {missing[0]}: hold out fewer pairs"
            )


def _swap_in(rng: np.random.Generator, others: list[ObjectProps], qualifying: list[ObjectProps]) -> None:
    """Replace a random one of ``others`` by a random qualifying object not among them yet (in place)."""
    fresh = [o for o in qualifying if o not in others]
    others[int(rng.integers(len(others)))] = fresh[int(rng.integers(len(fresh)))]


def sample_positions(
    rng: np.random.Generator, n: int, low: np.ndarray, high: np.ndarray, min_distance: float, max_tries: int = 1000
) -> np.ndarray:
    """``n`` points in the rectangle [low, high] no two closer than ``min_distance`` (rejection sampling)."""
    first, second = np.triu_indices(n, 1)  # every pair once; drawn before the loop, which tries dozens of times
    for _ in range(max_tries):
        points = rng.uniform(low, high, size=(n, 2))
        if n < 2 or np.linalg.norm(points[first] - points[second], axis=-1).min() >= min_distance:
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
    need_same_shape: bool = False,
    holdout: Holdout = NOTHING_HELD_OUT,
    split: Split | None = None,
) -> Scene:
    objects, goal_index = sample_objects(rng, mode, n_objects, need_shared, need_same_shape, holdout, split)
    positions = sample_positions(rng, n_objects, area_low, area_high, min_distance)
    return Scene(objects, goal_index, positions)
