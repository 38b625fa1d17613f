"""Run a policy for a number of episodes and report success the way the paper does: overall, on
correction episodes, per kind of misunderstanding and per form of the spoken correction; and, for agents
that attend to objects, how much of that attention lies on the goal before and after a correction.

Every success rate reported is one ``Figure`` of the registry ``FIGURES``: the columns of ``metrics.csv``,
``EvaluationReport.metrics``, the tables and ``lanro report`` are all generated from it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lanrocli.choices import CorrectionForm, Instruction, Kind
from lanrocli.language import TASK_VERBS, identifying_phrases, instruction, pick
from lanrocli.reward import reward

if TYPE_CHECKING:
    from lanrocli.envs.env import LanroEnv
    from lanrocli.envs.policies import Policy

GIF_EPISODES = 3

JUDGED = 30
"""Spoken corrections of one kind or form below which its success is shown but not judged: with fewer, its
95% interval spans more than about 35 points."""

PLAIN = "plain"
"""The phase of an episode before any correction was spoken; after one, the phase is the correction's form."""
PHASES = (PLAIN, *(form.value for form in CorrectionForm))
"""The phases over which the attention on the goal is averaged, in the order tables show them."""

ATTENTION = "attention_on_goal"
"""Key of the attention on the goal in records, and the stem of its columns (``attention_on_goal_plain``)."""


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
    form: CorrectionForm | None
    """The form of the correction spoken last, or None where none was spoken."""
    returned: float
    attention: Mapping[str, tuple[float, int]] = field(default_factory=dict)
    """Per phase (``PHASES``) the episode went through: the sum over its steps of the share of attention on
    the goal, and the number of those steps. Empty for a policy without attention."""

    @property
    def corrected(self) -> bool:
        """Whether a correction was spoken: derived from the form, so the forms split the corrected episodes."""
        return self.form is not None

    @property
    def negation(self) -> bool:
        return self.form is CorrectionForm.NEGATION


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

    @property
    def judged(self) -> bool:
        """Whether a rate of one kind or form rests on enough episodes to be judged (``JUDGED``)."""
        return self.episodes >= JUDGED

    def as_dict(self) -> dict[str, Any]:
        return {"episodes": self.episodes, "success": self.value, "ci": list(self.interval)}


def _rate(results: Sequence[EpisodeResult]) -> Rate:
    return Rate(len(results), sum(r.success for r in results))


@dataclass(frozen=True)
class Figure:
    """One success rate that every tool reports alike: the episodes it counts, its two columns of
    ``metrics.csv``, its words in tables, and where an ``EvaluationReport.as_dict`` record keeps it."""

    name: str
    """Column of the success rate."""
    count: str
    """Column of the number of episodes it counts."""
    label: str
    counts: Callable[[EpisodeResult], bool]
    where: tuple[str, ...]
    """Keys leading to the mapping of a record that holds its episodes and success."""
    keys: tuple[str, str] = ("episodes", "success")
    """The keys of the episodes and the success in that mapping."""
    split: bool = False
    """A share of the spoken corrections (one kind or one form), judged only from ``JUDGED`` episodes on."""
    older: tuple[str, ...] | None = None
    """Where records written before ``where`` existed keep the figure."""

    def rate(self, results: Sequence[EpisodeResult]) -> Rate:
        return _rate([r for r in results if self.counts(r)])

    def read(self, record: Mapping[str, Any]) -> tuple[int, float | None]:
        """Episodes and success of this figure in a record: (0, None) where it has none."""
        for where in (self.where, self.older):
            if where is None:
                continue
            node: Any = record
            for key in where:
                node = node.get(key) if isinstance(node, Mapping) else None
            if isinstance(node, Mapping) and node.get(self.keys[0]):
                return int(node[self.keys[0]]), node.get(self.keys[1])
        return 0, None


def _kind_figures(kind: Kind) -> tuple[Figure, Figure]:
    """Episodes set up with ``kind``, and those of them in which a correction was spoken."""
    words = kind.value.replace("_", " ")
    return (
        Figure(f"success_{kind}", f"episodes_{kind}", words, lambda r: r.challenge == kind, ("by_kind", kind)),
        Figure(
            f"corrected_success_{kind}",
            f"corrected_episodes_{kind}",
            words,
            lambda r: r.challenge == kind and r.corrected,
            ("by_kind", kind, "corrected"),
            split=True,
        ),
    )


def _form_figure(form: CorrectionForm) -> Figure:
    """Episodes whose spoken correction took ``form``; negations were kept under ``by_negation`` before."""
    article = "an" if form.value[0] in "aeiou" else "a"
    return Figure(
        f"corrected_success_{form}",
        f"corrected_episodes_{form}",
        f"after {article} {form}",
        lambda r: r.form is form,
        ("by_form", form),
        split=True,
        older=("by_negation", "with_negation") if form is CorrectionForm.NEGATION else None,
    )


FIGURES: tuple[Figure, ...] = (
    Figure("success", "episodes", "success", lambda r: True, ()),
    Figure(
        "correction_episode_success",
        "correction_episodes",
        "correction episodes",
        lambda r: r.challenge is not None,
        (),
        ("correction_episodes", "correction_episode_success"),
    ),
    Figure("corrected_success", "corrected_episodes", "corrected", lambda r: r.corrected, ("corrected",)),
    *(figure for kind in Kind for figure in _kind_figures(kind)),
    *(_form_figure(form) for form in CorrectionForm),
)
"""The registry of the success rates every tool reports."""

FIGURE = {figure.name: figure for figure in FIGURES}

METRIC_NAMES = (
    *(name for figure in FIGURES for name in (figure.count, figure.name)),
    *(f"{ATTENTION}_{phase}" for phase in PHASES),
)
"""The flat metrics of one evaluation (``EvaluationReport.metrics``), as ``metrics.csv`` names its columns."""


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
            "correction_episodes": episodes.episodes,
            "correction_episode_success": episodes.value,
            "correction_episode_success_ci": list(episodes.interval),
            "corrected": self.corrected.as_dict(),
            "by_kind": {
                k: {**r.as_dict(), "corrected": corrected_by_kind[k].as_dict()} for k, r in self.by_kind().items()
            },
            "by_form": {form: r.as_dict() for form, r in self.by_form().items()},
            "by_negation": {k: r.as_dict() for k, r in self.by_negation().items()},
            ATTENTION: self.attention_on_goal(),
        }


def _other_sentence(env: LanroEnv, info: dict[str, Any], seed: int) -> tuple[int, np.ndarray]:
    """An object other than the goal and an instruction that names it uniquely, drawn from the seed."""
    rng = np.random.default_rng([seed, OTHER_STREAM])
    objects = list(info["objects"])
    named = int(pick(rng, [i for i in range(len(objects)) if i != int(info["goal_index"])]))
    others = objects[:named] + objects[named + 1 :]
    text = instruction(pick(rng, TASK_VERBS[env.task.name]), pick(rng, identifying_phrases(objects[named], others)))
    return named, env.vocabulary.encode(text)


def _phase(info: dict[str, Any]) -> str:
    """The phase of the step about to be taken: plain, or the form of the correction spoken last."""
    correction = info["correction"]
    return PLAIN if correction is None else str(correction["form"])


Attend = Callable[[dict[str, np.ndarray]], np.ndarray | None]
"""A policy's optional ``attention(observation)``: its weights over the object slots (slot k is object k of
the observation), or None where it has none. Evaluation reads it without knowing what computes it, so this
module needs no torch; scripted policies have no such method."""


def run_episode(
    env: LanroEnv,
    policy: Policy,
    seed: int,
    frames: list[np.ndarray] | None = None,
    instruction_shown: Instruction = Instruction.TRUE,
) -> EpisodeResult:
    """One episode; with ``instruction_shown`` other than ``true`` the agent reads the replacement sentence
    all episode, and success, return and attention are judged on the object that sentence names."""
    observation, info = env.reset(seed=seed)
    policy.reset(seed=seed)
    attend: Attend | None = getattr(policy, "attention", None)
    target, tokens = int(info["goal_index"]), None
    if instruction_shown is Instruction.BLANK:
        tokens = np.zeros_like(observation["instruction"])
    elif instruction_shown is Instruction.OTHER:
        target, tokens = _other_sentence(env, info, seed)
    total, length = 0.0, 0
    shares: dict[str, list[float]] = {}
    if frames is not None:
        frames.append(env.render())
    while True:
        shown = observation if tokens is None else {**observation, "instruction": tokens}
        weights = None if attend is None else attend(shown)
        if weights is not None:
            shares.setdefault(_phase(info), []).append(float(weights[target]))
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
        form=None if correction is None else CorrectionForm(correction["form"]),
        returned=total,
        attention={phase: (sum(values), len(values)) for phase, values in shares.items()},
    )


def evaluate(
    env: LanroEnv,
    policy: Policy,
    episodes: int,
    seed: int,
    gif: Path | None = None,
    progress: Callable[[int], None] | None = None,
    instruction_shown: Instruction = Instruction.TRUE,
    enough: Callable[[EvaluationReport], bool] | None = None,
) -> EvaluationReport:
    """Episode i is reset with seed ``seed + i``, so every policy meets the very same episodes. With
    ``enough``, the run stops after the first episode at which it holds (``episodes`` is then the most run):
    the same episodes and policy always stop at the same one."""
    if gif is not None and env.render_mode != "rgb_array":
        raise ValueError("recording a GIF needs an environment made with render_mode='rgb_array'")
    report = EvaluationReport()
    frames: list[np.ndarray] = []
    for i in range(episodes):
        recording = gif is not None and i < GIF_EPISODES
        report.results.append(run_episode(env, policy, seed + i, frames if recording else None, instruction_shown))
        if progress is not None:
            progress(i + 1)
        if enough is not None and enough(report):
            break
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
