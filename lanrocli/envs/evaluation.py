"""Run a policy for a number of episodes and report success the way the paper does: overall, on
correction episodes, per kind of misunderstanding, and with or without negation."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lanrocli.choices import Instruction, Kind
from lanrocli.language import TASK_VERBS, identifying_phrases, instruction, pick
from lanrocli.reward import reward

if TYPE_CHECKING:
    from lanrocli.envs.env import LanroEnv
    from lanrocli.envs.policies import Policy

GIF_EPISODES = 3

METRIC_NAMES = (
    "episodes", "success", "correction_episodes", "correction_episode_success", "corrected_episodes",
    "corrected_success",
    *(f"{what}_{kind.value}" for kind in Kind for what in ("episodes", "success", "corrected_episodes", "corrected_success")),
    "corrected_episodes_negation", "corrected_success_negation",
)
"""The flat metrics of one evaluation (``EvaluationReport.metrics``), as ``metrics.csv`` names its columns."""


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95% Wilson score interval: unlike the normal approximation it stays inside [0, 1] for small n."""
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


OTHER_STREAM = 0x07E4
"""Mixed into an episode's seed to draw the object that ``other`` names, apart from the episode's own draws."""


@dataclass(frozen=True)
class EpisodeResult:
    success: bool
    length: int
    challenge: Kind | None
    """The misunderstanding the episode was set up with (a correction episode), or None."""
    corrected: bool
    """Whether a correction was spoken."""
    negation: bool
    returned: float


@dataclass(frozen=True)
class Rate:
    episodes: int
    successes: int

    @property
    def success(self) -> float:
        return self.successes / self.episodes if self.episodes else float("nan")

    @property
    def interval(self) -> tuple[float, float]:
        return wilson_interval(self.successes, self.episodes)

    @property
    def value(self) -> float | None:
        """The success rate, or None without episodes (where ``success`` is NaN)."""
        return self.success if self.episodes else None

    def as_dict(self) -> dict[str, Any]:
        return {"episodes": self.episodes, "success": self.value, "ci": list(self.interval)}


def _rate(results: list[EpisodeResult]) -> Rate:
    return Rate(len(results), sum(r.success for r in results))


@dataclass
class EvaluationReport:
    """Episode outcomes and the metrics every tool names alike: ``success`` (all episodes),
    ``correction_episode_success`` (episodes set up as correction episodes) and ``corrected_success``
    (episodes in which a correction was spoken: the paper's figure), per kind and by negation."""

    results: list[EpisodeResult] = field(default_factory=list)

    @property
    def overall(self) -> Rate:
        return _rate(self.results)

    @property
    def correction_episodes(self) -> Rate:
        return _rate([r for r in self.results if r.challenge is not None])

    @property
    def corrected(self) -> Rate:
        return _rate([r for r in self.results if r.corrected])

    def by_kind(self) -> dict[str, Rate]:
        """Episodes set up with each kind of misunderstanding, whether or not a correction was spoken."""
        kinds = sorted({r.challenge for r in self.results if r.challenge is not None})
        return {k: _rate([r for r in self.results if r.challenge == k]) for k in kinds}

    def corrected_by_kind(self) -> dict[str, Rate]:
        """Episodes of each kind in which that kind's correction was spoken."""
        return {k: _rate([r for r in self.results if r.challenge == k and r.corrected]) for k in self.by_kind()}

    def by_negation(self) -> dict[str, Rate]:
        """Among episodes in which a correction was spoken."""
        spoken = [r for r in self.results if r.corrected]
        return {
            "with_negation": _rate([r for r in spoken if r.negation]),
            "without_negation": _rate([r for r in spoken if not r.negation]),
        }

    @property
    def mean_length(self) -> float:
        return float(np.mean([r.length for r in self.results])) if self.results else float("nan")

    @property
    def mean_return(self) -> float:
        return float(np.mean([r.returned for r in self.results])) if self.results else float("nan")

    def metrics(self) -> dict[str, float | int | None]:
        """``METRIC_NAMES`` and their values; a success is None where there was no such episode."""
        empty = Rate(0, 0)
        kinds, corrected_kinds = self.by_kind(), self.corrected_by_kind()
        overall, episodes, corrected = self.overall, self.correction_episodes, self.corrected
        negation = self.by_negation()["with_negation"]
        values: dict[str, float | int | None] = {
            "episodes": overall.episodes,
            "success": overall.value,
            "correction_episodes": episodes.episodes,
            "correction_episode_success": episodes.value,
            "corrected_episodes": corrected.episodes,
            "corrected_success": corrected.value,
            "corrected_episodes_negation": negation.episodes,
            "corrected_success_negation": negation.value,
        }
        for kind in Kind:
            rate, spoken = kinds.get(kind.value, empty), corrected_kinds.get(kind.value, empty)
            values |= {
                f"episodes_{kind.value}": rate.episodes,
                f"success_{kind.value}": rate.value,
                f"corrected_episodes_{kind.value}": spoken.episodes,
                f"corrected_success_{kind.value}": spoken.value,
            }
        return {name: values[name] for name in METRIC_NAMES}

    def as_dict(self) -> dict[str, Any]:
        overall, episodes = self.overall, self.correction_episodes
        corrected_by_kind = self.corrected_by_kind()
        return {
            "episodes": overall.episodes,
            "success": overall.success,
            "success_ci": list(overall.interval),
            "mean_length": self.mean_length,
            "mean_return": self.mean_return,
            "correction_episodes": episodes.episodes,
            "correction_episode_success": episodes.value,
            "correction_episode_success_ci": list(episodes.interval),
            "corrected": self.corrected.as_dict(),
            "by_kind": {
                k: {**r.as_dict(), "corrected": corrected_by_kind[k].as_dict()} for k, r in self.by_kind().items()
            },
            "by_negation": {k: r.as_dict() for k, r in self.by_negation().items()},
        }


def _other_sentence(env: LanroEnv, info: dict[str, Any], seed: int) -> tuple[int, np.ndarray]:
    """An object other than the goal and an instruction that names it uniquely, drawn from the seed."""
    rng = np.random.default_rng([seed, OTHER_STREAM])
    objects = list(info["objects"])
    named = int(pick(rng, [i for i in range(len(objects)) if i != int(info["goal_index"])]))
    others = objects[:named] + objects[named + 1 :]
    text = instruction(pick(rng, TASK_VERBS[env.task.name]), pick(rng, identifying_phrases(objects[named], others)))
    return named, env.vocabulary.encode(text)


def run_episode(
    env: LanroEnv,
    policy: Policy,
    seed: int,
    frames: list[np.ndarray] | None = None,
    instruction_shown: Instruction = Instruction.TRUE,
) -> EpisodeResult:
    """One episode; with ``instruction_shown`` other than ``true`` the agent reads the replacement sentence
    all episode, and success and return are judged on the object that sentence names."""
    observation, info = env.reset(seed=seed)
    policy.reset(seed=seed)
    target, tokens = int(info["goal_index"]), None
    if instruction_shown is Instruction.BLANK:
        tokens = np.zeros_like(observation["instruction"])
    elif instruction_shown is Instruction.OTHER:
        target, tokens = _other_sentence(env, info, seed)
    total, length = 0.0, 0
    if frames is not None:
        frames.append(env.render())
    while True:
        shown = observation if tokens is None else {**observation, "instruction": tokens}
        observation, _, terminated, truncated, info = env.step(policy.act(shown, info))
        achieved = bool(info["achieved"][target])
        total += reward(achieved)
        length += 1
        if frames is not None:
            frames.append(env.render())
        if terminated or truncated or achieved:
            break
    correction = info["correction"]
    return EpisodeResult(
        success=achieved,
        length=length,
        challenge=info["challenge"],
        corrected=correction is not None,
        negation=bool(correction and correction["negation"]),
        returned=total,
    )


def evaluate(
    env: LanroEnv,
    policy: Policy,
    episodes: int,
    seed: int,
    gif: Path | None = None,
    progress: Callable[[int], None] | None = None,
    instruction_shown: Instruction = Instruction.TRUE,
) -> EvaluationReport:
    """Episode i is reset with seed ``seed + i``, so every policy meets the very same episodes."""
    if gif is not None and env.render_mode != "rgb_array":
        raise ValueError("recording a GIF needs an environment made with render_mode='rgb_array'")
    report = EvaluationReport()
    frames: list[np.ndarray] = []
    for i in range(episodes):
        recording = gif is not None and i < GIF_EPISODES
        report.results.append(run_episode(env, policy, seed + i, frames if recording else None, instruction_shown))
        if progress is not None:
            progress(i + 1)
    if gif is not None:
        save_gif(frames, gif, env.metadata["render_fps"])
    return report


def save_gif(frames: list[np.ndarray], path: Path, fps: int) -> None:
    from PIL import Image

    images = [Image.fromarray(f) for f in frames if f is not None]
    if not images:
        raise ValueError("no frames to write")
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
