"""Episodes run for measurement, one after another or several side by side.

A network asked one observation at a time pays its fixed cost per call for every step of every episode.
Run side by side, the episodes in progress are answered in one batch per step (a policy with
``act_batch``), which costs little more than one of them. Episode ``i`` is always reset with seed
``first + i`` and its result is reported in index order, so side by side or not, a policy meets the same
episodes and a stopping rule stops at the same one.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from lanrocli.core.choices import CorrectionForm, Instruction
from lanrocli.core.reward import reward
from lanrocli.evaluation.metrics import PLAIN, EpisodeResult
from lanrocli.language import TASK_VERBS, identifying_phrases, instruction, pick

if TYPE_CHECKING:
    from lanrocli.envs.env import LanroEnv
    from lanrocli.envs.policies import Policy

OTHER_STREAM = 0x07E4
"""Mixed into an episode's seed to draw the object that ``other`` names, apart from the episode's own draws."""

Attend = Callable[[dict[str, np.ndarray]], np.ndarray | None]
"""A policy's optional ``attention(observation)``: its weights over the object slots (slot k is object k of
the observation), or None where it has none. Evaluation reads it without knowing what computes it, so this
module needs no torch; scripted policies have no such method."""


class PolicyError(ValueError):
    """A policy raised, or answered with something that is not an action, in a named episode and step."""


class BatchPolicy(Protocol):
    """A policy that answers several observations at once: ``act_batch`` takes them stacked (``[B, ...]``
    per key) and returns the actions ``[B, A]`` and its attention over the object slots ``[B, slots]``, or
    None where it has none. It keeps no state between steps, so one instance serves every episode."""

    def act_batch(self, observations: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray | None]: ...


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


@dataclass
class Episode:
    """One episode in progress in ``env``: what the policy is shown next, and the tally of its result. With
    ``instruction_shown`` other than ``true`` the agent reads the replacement sentence all episode, and
    success, return and attention are judged on the object that sentence names."""

    env: LanroEnv
    seed: int
    instruction_shown: Instruction = Instruction.TRUE
    frames: list[np.ndarray] | None = None
    observation: dict[str, np.ndarray] = field(init=False)
    info: dict[str, Any] = field(init=False)
    target: int = field(init=False)
    tokens: np.ndarray | None = field(init=False, default=None)
    total: float = field(init=False, default=0.0)
    length: int = field(init=False, default=0)
    shares: dict[str, list[float]] = field(init=False, default_factory=dict)
    named_first: bool | None = field(init=False, default=None)
    wrong_objects: int = field(init=False, default=0)
    achieved: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.observation, self.info = self.env.reset(seed=self.seed)
        self.target = int(self.info["goal_index"])
        self.achieved = np.asarray(self.info["achieved"], dtype=bool)
        if self.instruction_shown is Instruction.BLANK:
            self.tokens = np.zeros_like(self.observation["instruction"])
        elif self.instruction_shown is Instruction.OTHER:
            self.target, self.tokens = _other_sentence(self.env, self.info, self.seed)
        if self.frames is not None:
            self.frames.append(self.env.render())

    @property
    def shown(self) -> dict[str, np.ndarray]:
        """The observation as the policy sees it, its sentence replaced where the episode says so."""
        return self.observation if self.tokens is None else {**self.observation, "instruction": self.tokens}

    def attend(self, weights: np.ndarray | None) -> None:
        """Tally the policy's attention ``weights`` on the observation about to be acted on."""
        if weights is not None:
            self.shares.setdefault(_phase(self.info), []).append(float(weights[self.target]))

    def stepped(self, outcome: tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]) -> EpisodeResult | None:
        """Take in what the environment's ``step`` returned for the action chosen on :attr:`shown`; the
        episode's result once it has ended, else None."""
        self.observation, _, terminated, truncated, self.info = outcome
        holds = np.asarray(self.info["achieved"], dtype=bool)
        achieved = bool(holds[self.target])
        if self.named_first is None and np.any(holds):
            self.named_first = achieved
        began = holds & ~self.achieved
        began[self.target] = False
        self.wrong_objects += int(began.sum())
        self.achieved = holds
        self.total += reward(achieved)
        self.length += 1
        if self.frames is not None:
            self.frames.append(self.env.render())
        if not (terminated or truncated or achieved):
            return None
        correction = self.info["correction"]
        return EpisodeResult(
            success=achieved,
            length=self.length,
            challenge=self.info["challenge"],
            form=None if correction is None else CorrectionForm(correction["form"]),
            returned=self.total,
            attention={phase: (sum(values), len(values)) for phase, values in self.shares.items()},
            corrections=0 if correction is None else int(correction["index"]),
            named_first=bool(self.named_first),
            phrasing=None if correction is None else correction.get("phrasing"),
            answers=tuple(answer["text"] for answer in self.info["answers"]),
            asked_at=tuple(answer["asked_at"] for answer in self.info["answers"]),
            wrong_objects=self.wrong_objects,
            fits=int(self.info["fits"]),
        )


def _where(episode: Episode, first: int) -> str:
    return f"episode {episode.seed - first} (seed {episode.seed}), step {episode.length}"


def checked_action(action: Any, episode: Episode, first: int) -> np.ndarray:
    """``action`` as the environment takes it, or a :class:`PolicyError` that names the episode and step:
    the shape of the action space and finite numbers (the environment clips them to [-1, 1])."""
    expected = episode.env.action_space.shape
    try:
        array = np.asarray(action, dtype=np.float64)  # as the environment takes it: a float64 action stays exact
    except (TypeError, ValueError) as error:
        raise PolicyError(f"the policy's action in {_where(episode, first)} is not numbers: {error}") from None
    if array.shape != expected:
        raise PolicyError(
            f"the policy's action in {_where(episode, first)} has shape {array.shape}; the task's actions have "
            f"shape {expected}"
        )
    if not np.all(np.isfinite(array)):
        raise PolicyError(f"the policy's action in {_where(episode, first)} is not finite: {array.tolist()}")
    return array


def _asked(call: Callable[[], Any], episode: Episode, first: int) -> Any:
    """``call()``, its exception turned into a :class:`PolicyError` naming where it happened."""
    try:
        return call()
    except PolicyError:
        raise
    except Exception as error:
        raise PolicyError(f"the policy raised {type(error).__name__} in {_where(episode, first)}: {error}") from error


def _decide(
    policies: Sequence[Policy], episodes: Sequence[Episode], width: int, first: int
) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """Each episode's action and the policy's attention there: one batch for a :class:`BatchPolicy`, else
    each episode asks its own policy. A batch is padded to ``width`` rows (the first repeated), so that a
    network computes every batch at one size, however many episodes are left. Which episodes share a batch
    still rounds the last bits of each one's numbers, so measurement plays fixed blocks of episodes
    (:mod:`lanrocli.evaluation.blocks`)."""
    act_batch = getattr(policies[0], "act_batch", None)
    if act_batch is not None:
        shown = [episode.shown for episode in episodes]
        rows = shown + [shown[0]] * (width - len(shown))
        stacked = {key: np.stack([s[key] for s in rows]) for key in shown[0]}
        actions, weights = _asked(lambda: act_batch(stacked), episodes[0], first)
        return [
            (checked_action(actions[i], episode, first), None if weights is None else weights[i])
            for i, episode in enumerate(episodes)
        ]
    decisions = []
    for policy, episode in zip(policies, episodes):
        attend: Attend | None = getattr(policy, "attention", None)
        shown = episode.shown
        weights = None if attend is None else attend(shown)
        action = _asked(lambda p=policy, s=shown, e=episode: p.act(s, e.info), episode, first)
        decisions.append((checked_action(action, episode, first), weights))
    return decisions


def _step(envs: Sequence[LanroEnv], actions: Sequence[np.ndarray]) -> list[tuple]:
    """Each environment's ``step`` outcome; environments in workers (:mod:`lanrocli.envs.workers`) all
    start stepping before the first is waited for, so their physics runs on several cores at once."""
    if all(hasattr(env, "step_async") for env in envs):
        for env, action in zip(envs, actions):
            env.step_async(action)
        return [env.step_wait() for env in envs]
    return [env.step(action) for env, action in zip(envs, actions)]


def run_episodes(
    envs: Sequence[LanroEnv],
    policy: Policy,
    episodes: int,
    first: int,
    on_result: Callable[[EpisodeResult], bool],
    instruction_shown: Instruction = Instruction.TRUE,
    frames: Callable[[int], list[np.ndarray] | None] = lambda _: None,
    origin: int | None = None,
) -> None:
    """Episodes ``first``, ``first + 1``, ... (at most ``episodes``), as many at a time as there are
    ``envs``; ``on_result`` gets each result in episode order and returns whether to go on. ``frames(i)``:
    where episode ``i`` records its frames, if anywhere. ``origin``: the seed errors count episodes from
    (default ``first``), where these episodes are a part of a longer run.

    A scripted policy keeps state within an episode, so each environment's episodes get a copy of it; a
    :class:`BatchPolicy` keeps none and answers all of them at once.
    """
    batched = hasattr(policy, "act_batch")
    policies = [policy if batched or k == 0 else copy.deepcopy(policy) for k in range(len(envs))]
    running: dict[int, tuple[int, Episode]] = {}  # environment -> (episode index, episode)
    finished: dict[int, EpisodeResult] = {}
    started = reported = 0
    origin = first if origin is None else origin
    while reported < episodes:
        for k in range(len(envs)):
            if k not in running and started < episodes:
                reset = getattr(policies[k], "reset", None)
                if reset is not None:
                    reset(seed=first + started)
                episode = Episode(envs[k], first + started, instruction_shown, frames(started))
                running[k], started = (started, episode), started + 1
        slots = sorted(running)
        decisions = _decide([policies[k] for k in slots], [running[k][1] for k in slots], len(envs), origin)
        for k, (_, weights) in zip(slots, decisions):
            running[k][1].attend(weights)
        for k, outcome in zip(slots, _step([envs[k] for k in slots], [action for action, _ in decisions])):
            index, episode = running[k]
            result = episode.stepped(outcome)
            if result is not None:
                finished[index] = result
                del running[k]
        while reported in finished:
            if not on_result(finished.pop(reported)):
                return
            reported += 1
