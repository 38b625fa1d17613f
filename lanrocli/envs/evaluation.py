"""Run a policy for a number of episodes and report success the way the paper does: overall, on
correction episodes, per kind of misunderstanding, and with or without negation."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lanrocli.envs.env import LanroEnv
from lanrocli.envs.policies import Policy

GIF_EPISODES = 3


def evaluation_settings(env: Mapping[str, Any]) -> dict[str, Any]:
    """A stage's environment settings as evaluation uses them: every episode starts from the neutral pose
    (random starts are for training), so success is comparable across runs and curricula."""
    return {**env, "random_start": 0.0}


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95% Wilson score interval: unlike the normal approximation it stays inside [0, 1] for small n."""
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


@dataclass(frozen=True)
class EpisodeResult:
    success: bool
    length: int
    challenge: str | None
    corrected: bool
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

    def as_dict(self) -> dict[str, Any]:
        success = self.success if self.episodes else None
        return {"episodes": self.episodes, "success": success, "success_ci": list(self.interval)}


def _rate(results: list[EpisodeResult]) -> Rate:
    return Rate(len(results), sum(r.success for r in results))


@dataclass
class EvaluationReport:
    results: list[EpisodeResult] = field(default_factory=list)

    @property
    def overall(self) -> Rate:
        return _rate(self.results)

    @property
    def corrections(self) -> Rate:
        return _rate([r for r in self.results if r.challenge is not None])

    def by_kind(self) -> dict[str, Rate]:
        kinds = sorted({r.challenge for r in self.results if r.challenge is not None})
        return {k: _rate([r for r in self.results if r.challenge == k]) for k in kinds}

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

    def as_dict(self) -> dict[str, Any]:
        overall, corrections = self.overall, self.corrections
        return {
            "episodes": overall.episodes,
            "success": overall.success,
            "success_ci": list(overall.interval),
            "mean_length": self.mean_length,
            "mean_return": self.mean_return,
            "correction_episodes": corrections.episodes,
            "correction_success": corrections.success if corrections.episodes else None,
            "correction_success_ci": list(corrections.interval),
            "by_kind": {k: r.as_dict() for k, r in self.by_kind().items()},
            "by_negation": {k: r.as_dict() for k, r in self.by_negation().items()},
        }


def run_episode(
    env: LanroEnv, policy: Policy, seed: int, frames: list[np.ndarray] | None = None
) -> EpisodeResult:
    observation, info = env.reset(seed=seed)
    policy.reset(seed=seed)
    total, length = 0.0, 0
    if frames is not None:
        frames.append(env.render())
    while True:
        observation, reward, terminated, truncated, info = env.step(policy.act(observation, info))
        total += float(reward)
        length += 1
        if frames is not None:
            frames.append(env.render())
        if terminated or truncated:
            break
    correction = info["correction"]
    return EpisodeResult(
        success=bool(info["is_success"]),
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
) -> EvaluationReport:
    """Episode i is reset with seed ``seed + i``, so every policy meets the very same episodes."""
    if gif is not None and env.render_mode != "rgb_array":
        raise ValueError("recording a GIF needs an environment made with render_mode='rgb_array'")
    report = EvaluationReport()
    frames: list[np.ndarray] = []
    for i in range(episodes):
        recording = gif is not None and i < GIF_EPISODES
        report.results.append(run_episode(env, policy, seed + i, frames if recording else None))
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
