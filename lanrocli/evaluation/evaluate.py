"""Run a policy for a number of episodes and report success the way the paper does: overall, on
correction episodes, per kind of misunderstanding and per form of the spoken correction; and, for agents
that attend to objects, how much of that attention lies on the goal before and after a correction. The
figures themselves are the registry of :mod:`lanrocli.evaluation.metrics`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lanrocli.core.choices import CorrectionForm, Instruction
from lanrocli.envs.instructor import MAX_CORRECTIONS
from lanrocli.evaluation.metrics import ATTENTION, FIGURE, FIGURES, PHASES, EpisodeResult, Rate, _rate
from lanrocli.evaluation.rollout import run_episodes

if TYPE_CHECKING:
    from lanrocli.envs.env import LanroEnv
    from lanrocli.envs.policies import Policy

GIF_EPISODES = 3

SIDE_BY_SIDE = 4
"""How many episodes a run's evaluations and tests play side by side. Fixed, not the machine's core count:
a network's batched arithmetic rounds in the last bit differently for other batch sizes, which can change
an episode's outcome, so the same checkpoint must always be measured with the same number."""


@dataclass
class EvaluationReport:
    """Episode outcomes and the metrics every tool names alike: ``success`` (all episodes),
    ``correction_episode_success`` (episodes set up as correction episodes) and ``corrected_success``
    (episodes in which a correction was spoken: the paper's figure), per kind and per form."""

    results: list[EpisodeResult] = field(default_factory=list)

    def rate(self, name: str) -> Rate:
        """The rate of the figure ``name`` (``FIGURES``) on these episodes."""
        return FIGURE[name].rate(self.results)

    @property
    def overall(self) -> Rate:
        return self.rate("success")

    @property
    def correction_episodes(self) -> Rate:
        return self.rate("correction_episode_success")

    @property
    def corrected(self) -> Rate:
        return self.rate("corrected_success")

    @property
    def named_first(self) -> Rate:
        """All episodes, counted as won where the first object the task's condition held for was the one the
        sentence names: with a blank sentence, a policy that picks an object at random gets 1/objects here
        whatever it does after a wrong one (:attr:`EpisodeResult.named_first`)."""
        return Rate(len(self.results), sum(r.named_first for r in self.results))

    def by_kind(self) -> dict[str, Rate]:
        """Episodes set up with each kind of misunderstanding met, whether or not a correction was spoken."""
        kinds = sorted({r.challenge for r in self.results if r.challenge is not None})
        return {kind: self.rate(f"success_{kind}") for kind in kinds}

    def corrected_by_kind(self) -> dict[str, Rate]:
        """Episodes of each kind met in which a correction was spoken."""
        return {kind: self.rate(f"corrected_success_{kind}") for kind in self.by_kind()}

    def by_form(self) -> dict[str, Rate]:
        """Episodes in which a correction was spoken, by the form of the last one; every form, met or not,
        so that a reader sees a form that was never spoken as 0 episodes."""
        return {form.value: self.rate(f"corrected_success_{form}") for form in CorrectionForm}

    def by_negation(self) -> dict[str, Rate]:
        """Among episodes in which a correction was spoken: records keep it for readers of older runs."""
        spoken = [r for r in self.results if r.corrected]
        return {
            "with_negation": _rate([r for r in spoken if r.negation]),
            "without_negation": _rate([r for r in spoken if not r.negation]),
        }

    def by_phrasing(self) -> dict[str, Rate]:
        """Among episodes in which a correction was spoken, by the paraphrase it was spoken in (the
        paraphrase split; ``grammar`` where no paraphrase fitted): how often each phrasing was followed.
        Which phrasing fits depends on the scene, so these are not paired with the control."""
        spoken = [r for r in self.results if r.corrected]
        names = sorted({r.phrasing or "grammar" for r in spoken})
        return {name: _rate([r for r in spoken if (r.phrasing or "grammar") == name]) for name in names}

    def attention_on_goal(self) -> dict[str, float | None] | None:
        """Per phase, the mean over all its steps of the share of the policy's attention on the goal object
        (None for a phase without steps); None when the policy had no attention to measure."""
        if not any(r.attention for r in self.results):
            return None
        means: dict[str, float | None] = {}
        for phase in PHASES:
            total = sum(r.attention[phase][0] for r in self.results if phase in r.attention)
            steps = sum(r.attention[phase][1] for r in self.results if phase in r.attention)
            means[phase] = total / steps if steps else None
        return means

    @property
    def _paraphrased(self) -> bool:
        return any(r.phrasing for r in self.results)

    @property
    def mean_length(self) -> float:
        return float(np.mean([r.length for r in self.results])) if self.results else float("nan")

    @property
    def mean_return(self) -> float:
        return float(np.mean([r.returned for r in self.results])) if self.results else float("nan")

    def metrics(self) -> dict[str, float | int | None]:
        """``METRIC_NAMES`` and their values; a success or attention is None where there was nothing to measure."""
        values: dict[str, float | int | None] = {}
        for figure in FIGURES:
            rate = figure.rate(self.results)
            values |= {figure.count: rate.episodes, figure.name: rate.value}
        attention = self.attention_on_goal() or {}
        values |= {f"{ATTENTION}_{phase}": attention.get(phase) for phase in PHASES}
        return values

    def as_dict(self) -> dict[str, Any]:
        overall, episodes = self.overall, self.correction_episodes
        corrected_by_kind = self.corrected_by_kind()
        return {
            "episodes": overall.episodes,
            "success": overall.success,
            "success_ci": list(overall.interval),
            "mean_length": self.mean_length,
            "mean_return": self.mean_return,
            "named_first": self.named_first.as_dict(),
            "correction_episodes": episodes.episodes,
            "correction_episode_success": episodes.value,
            "correction_episode_success_ci": list(episodes.interval),
            "corrected": self.corrected.as_dict(),
            "by_kind": {
                k: {**r.as_dict(), "corrected": corrected_by_kind[k].as_dict()} for k, r in self.by_kind().items()
            },
            "by_form": {form: r.as_dict() for form, r in self.by_form().items()},
            "by_index": {
                str(i): self.rate(f"corrected_success_after_{i}").as_dict() for i in range(2, MAX_CORRECTIONS + 1)
            },
            "by_negation": {k: r.as_dict() for k, r in self.by_negation().items()},
            **({"by_phrasing": {k: r.as_dict() for k, r in self.by_phrasing().items()}} if self._paraphrased else {}),
            ATTENTION: self.attention_on_goal(),
        }


def evaluate(
    env: LanroEnv | Sequence[LanroEnv],
    policy: Policy,
    episodes: int,
    seed: int,
    gif: Path | None = None,
    progress: Callable[[int], None] | None = None,
    instruction_shown: Instruction = Instruction.TRUE,
    enough: Callable[[EvaluationReport], bool] | None = None,
) -> EvaluationReport:
    """Episode i is reset with seed ``seed + i``, so every policy meets the very same episodes; given several
    environments (alike), as many episodes run side by side (:mod:`lanrocli.evaluation.rollout`). With
    ``enough``, the run stops after the first episode at which it holds (``episodes`` is then the most run):
    the same episodes and policy always stop at the same one."""
    envs = list(env) if isinstance(env, Sequence) else [env]
    if gif is not None and any(e.render_mode != "rgb_array" for e in envs):
        raise ValueError("recording a GIF needs environments made with render_mode='rgb_array'")
    report = EvaluationReport()
    recordings: dict[int, list[np.ndarray]] = {i: [] for i in range(GIF_EPISODES)} if gif is not None else {}

    def on_result(result: EpisodeResult) -> bool:
        report.results.append(result)
        if progress is not None:
            progress(len(report.results))
        return enough is None or not enough(report)

    run_episodes(envs, policy, episodes, seed, on_result, instruction_shown, recordings.get)
    if gif is not None:
        save_gif([frame for i in sorted(recordings) for frame in recordings[i]], gif, envs[0].metadata["render_fps"])
    return report


def save_gif(frames: list[np.ndarray], path: Path, fps: int) -> None:
    from PIL import Image

    images = [Image.fromarray(f) for f in frames if f is not None]
    if not images:
        raise ValueError("no frames to write")
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
