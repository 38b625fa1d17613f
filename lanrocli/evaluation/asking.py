"""Asking "which one?" instead of guessing: a calibrated rule on the agent's attention, and what the
questions came to, per kind of episode.

The agent's attention over the objects, read on the sentence it has heard, is a distribution over what the
sentence may mean. The rule keeps every object whose weight reaches a threshold and asks whenever that
leaves other than exactly one object. The threshold is fitted by split conformal prediction on scenes of
their own (:func:`calibrate`): on a share ``level`` of fresh scenes the object the speaker means keeps its
place, so an agent that acts without asking acts on the meant object at least that often (in expectation
over calibration sets), and asks only where its reading is in doubt. On an ambiguous sentence an agent puts
most of its attention on the object it guesses, so a fixed threshold would rarely ask (docs/lab); the
calibrated one is low enough to catch the trace left on the other objects the sentence fits. A sentence read
without such a trace is not asked about, even where the speaker named the wrong object (an instruction
correction): no question can reveal that.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from lanrocli.core.choices import Kind
from lanrocli.evaluation.metrics import EpisodeResult, Rate, _rate

if TYPE_CHECKING:
    from lanrocli.envs.env import LanroEnv
    from lanrocli.evaluation.rollout import BatchPolicy

CLEAR = "clear"
"""Episodes whose instruction singles out the goal: plain ones, and those where the arm's own mistake is
corrected (``wrong_object``)."""
GROUPS = (CLEAR, Kind.AMBIGUITY.value, Kind.COMMON_GROUND.value, Kind.INSTRUCTION_CORRECTION.value)
"""The kinds of episode questions are reported on, in the order tables show them."""


def group(result: EpisodeResult) -> str:
    if result.challenge is None or result.challenge is Kind.WRONG_OBJECT:
        return CLEAR
    return Kind(result.challenge).value


@dataclass(frozen=True)
class Calibration:
    """The rule's threshold and what it was fitted on."""

    level: float
    """The share of scenes on which the meant object is kept: the agent acts without asking on the meant
    object at least this often."""
    threshold: float
    episodes: int
    first_seed: int

    def as_dict(self) -> dict[str, Any]:
        return {
            "level": self.level,
            "threshold": self.threshold,
            "episodes": self.episodes,
            "first_seed": self.first_seed,
        }


def conformal_threshold(weights_on_meant: Sequence[float], level: float) -> float:
    """The weight an object needs to be kept so that, on a fresh scene from the same distribution, the meant
    object is kept with probability at least ``level``: split conformal prediction with the score
    ``1 - weight``. Too few scenes for the level give 0 (keep everything: always ask)."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"the level must lie strictly between 0 and 1, got {level}")
    scores = np.sort(1.0 - np.asarray(weights_on_meant, dtype=np.float64))
    rank = math.ceil((len(scores) + 1) * level)
    if rank > len(scores):
        return 0.0
    return float(1.0 - scores[rank - 1])


def kept(weights: np.ndarray, threshold: float) -> np.ndarray:
    """The objects the rule keeps: present (a weight above 0) and weighing at least ``threshold``."""
    return (weights > 0.0) & (weights >= threshold)


@dataclass
class AskingPolicy:
    """A policy with attention that asks whenever its attention keeps other than one object. It answers as a
    :class:`~lanrocli.evaluation.rollout.BatchPolicy` in environments with questions: its policy's actions
    with one number more, 1 to ask and -1 not to (the environment hears a question only while one is left)."""

    policy: BatchPolicy
    threshold: float

    def act_batch(self, observations: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray | None]:
        actions, weights = self.policy.act_batch(observations)
        if weights is None:
            raise ValueError("asking needs a policy with attention over the objects (architecture: objects)")
        asks = np.array([kept(row, self.threshold).sum() != 1 for row in weights])
        return np.concatenate([actions, np.where(asks, 1.0, -1.0)[:, None]], axis=1), weights


def weights_on_meant(env: LanroEnv, policy: BatchPolicy, episodes: int, first: int, width: int) -> list[float]:
    """The policy's attention on the object the speaker means, on the first observation of episodes
    ``first``, ``first + 1``, ...: the instruction alone, before the arm moves. Batches are ``width`` rows
    (padded), as the rollout asks them, so the weights are those the rule meets there."""
    found: list[float] = []
    for start in range(first, first + episodes, width):
        scenes = [env.reset(seed=seed) for seed in range(start, min(start + width, first + episodes))]
        rows = [observation for observation, _ in scenes]
        rows += [rows[0]] * (width - len(rows))
        _, weights = policy.act_batch({key: np.stack([row[key] for row in rows]) for key in rows[0]})
        if weights is None:
            raise ValueError("asking needs a policy with attention over the objects (architecture: objects)")
        found += [float(weights[i][info["referent"]]) for i, (_, info) in enumerate(scenes)]
    return found


def calibrate(env: LanroEnv, policy: BatchPolicy, episodes: int, first: int, level: float, width: int) -> Calibration:
    """Fit the rule's threshold on ``episodes`` scenes of ``env`` from seed ``first`` (none of a test's)."""
    threshold = conformal_threshold(weights_on_meant(env, policy, episodes, first, width), level)
    return Calibration(level, threshold, episodes, first)


def _interval(values: Sequence[int]) -> list[float]:
    """A 95% interval of a mean count (normal approximation; [0, 0] where every count is 0)."""
    if not values:
        return [0.0, 0.0]
    mean = float(np.mean(values))
    half = 1.96 * float(np.std(values, ddof=1)) / math.sqrt(len(values)) if len(values) > 1 else 0.0
    return [max(0.0, mean - half), mean + half]


def questions_record(results: Sequence[EpisodeResult]) -> dict[str, dict[str, Any]]:
    """Per kind of episode met (``GROUPS``): the episodes with a question (and how many of them asked before
    the arm's first move), questions per episode, success, and the actions on a wrong object per episode,
    with 95% intervals and counts."""
    record: dict[str, dict[str, Any]] = {}
    for name in GROUPS:
        met = [r for r in results if group(r) == name]
        if not met:
            continue
        questions = [r.questions for r in met]
        wrong = [r.wrong_objects for r in met]
        record[name] = {
            "episodes": len(met),
            "asked": Rate(len(met), sum(q > 0 for q in questions)).as_dict(),
            "questions": {
                "total": sum(questions),
                "per_episode": float(np.mean(questions)),
                "ci": _interval(questions),
            },
            "asked_before_acting": sum(r.asked_at[:1] == (0,) for r in met),
            "success": _rate(met).as_dict(),
            "wrong_objects": {"total": sum(wrong), "per_episode": float(np.mean(wrong)), "ci": _interval(wrong)},
        }
    return record


def asked_by_fits(results: Sequence[EpisodeResult]) -> dict[str, dict[str, Any]]:
    """The episodes with a question by how many objects their instruction may mean (``EpisodeResult.fits``):
    how the asking rate grows with the ambiguity of what was said."""
    return {
        str(fits): Rate(len(met), sum(r.questions > 0 for r in met)).as_dict()
        for fits in sorted({r.fits for r in results})
        for met in [[r for r in results if r.fits == fits]]
    }
