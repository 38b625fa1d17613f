"""Training on one stage's environments: collect with N environments, learn, evaluate, checkpoint.

The trainer owns every piece of state a run has (agent, replay buffer, sampling generator, environments
mid-episode, counters) and can write all of it to a checkpoint and continue from one as if it had never
stopped: on CPU, N steps straight and N/2 + save + load + N/2 give identical parameters. When to evaluate,
where checkpoints go and when a stage ends is the curriculum's business (:mod:`lanrocli.train.pipeline`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lanrocli.agent.buffer.replay_buffer import ReplayBuffer
from lanrocli.agent.networks import ObjectLayout
from lanrocli.agent.policy import AgentPolicy
from lanrocli.agent.sac import SACAgent
from lanrocli.agent.settings import BufferSettings, SACSettings
from lanrocli.core.choices import check_device
from lanrocli.envs.env import ARM_SIZE, OBJECT_SIZE, LanroEnv, observation_size
from lanrocli.envs.settings import EnvSettings
from lanrocli.envs.workers import EnvWorker, make_envs
from lanrocli.evaluation.evaluate import SIDE_BY_SIDE, EvaluationReport, evaluate
from lanrocli.language import Vocabulary, agent_vocabulary, grammar_vocabulary
from lanrocli.language.holdout import NOTHING_HELD_OUT, Holdout
from lanrocli.sim import action_size
from lanrocli.tasks import Task, task_class
from lanrocli.train.checkpoint import Checkpoint, load_checkpoint, resolve_checkpoint, save_checkpoint
from lanrocli.train.clock import PhaseClock
from lanrocli.train.collect import Collector
from lanrocli.train.errors import CheckpointError

SUCCESS_WINDOW = 100
"""Training episodes over which the reported training success is averaged."""


def updates_due(env_steps: int, envs: int, updates_per_step: float) -> int:
    """Updates owed for the ``envs`` steps collected after ``env_steps``: the whole updates that
    ``updates_per_step`` accrues over them, so that fractions add up over the run. It depends on the step
    count alone, which a checkpoint holds, so a resumed run updates when the uninterrupted one would."""
    return math.floor((env_steps + envs) * updates_per_step) - math.floor(env_steps * updates_per_step)


@dataclass(frozen=True)
class TrainSettings:
    """What training one stage needs besides the agent's own settings."""

    task: Task = Task.REACH
    env: EnvSettings = field(default_factory=EnvSettings)
    seed: int = 0
    envs: int = 1
    eval_episodes: int = 20
    eval_correction_rate: float | None = None
    """Correction episodes' share in evaluations where the stage speaks corrections; ``None``: the stage's."""
    learning_starts: int = 1000
    """Environment steps collected before the first update."""
    updates_per_step: float = 1.0
    """Gradient updates per collected environment step; a fraction such as 0.5 updates every other step."""
    buffer: BufferSettings = field(default_factory=BufferSettings)
    object_slots: int | None = None
    """Objects the observation and the buffer have room for; ``None``: the stage's objects. A curriculum
    sets the most objects of any of its stages, so one network serves all of them."""
    stage: int = 0
    """Index of the stage in its curriculum: the environments of each stage get their own seeds."""
    max_corrections: int | None = None
    """The most corrections any stage speaks in one episode: the sentences the agent reads have room for
    them from the start; ``None``: the stage's."""
    holdout: Holdout = NOTHING_HELD_OUT
    """What the curriculum keeps out of training, to test the final agent on (its generalisation splits)."""

    def __post_init__(self) -> None:
        if self.envs < 1:
            raise ValueError(f"envs must be at least 1, got {self.envs}")
        if self.eval_episodes < 1:
            raise ValueError("eval_episodes must be positive")
        if self.updates_per_step < 0:
            raise ValueError(f"updates_per_step must not be negative, got {self.updates_per_step}")
        if self.learning_starts < 0:
            raise ValueError(f"learning_starts must not be negative, got {self.learning_starts}")
        object.__setattr__(self, "task", Task(self.task))
        if self.object_slots is not None and self.object_slots < self.env.objects:
            raise ValueError(f"object_slots {self.object_slots} is fewer than the stage's objects")

    @property
    def sentence_corrections(self) -> int:
        """How many corrections the agent's sentences have room for."""
        return max(self.max_corrections or 1, self.env.max_corrections)

    @property
    def in_workers(self) -> bool:
        """Whether environments run in subprocesses: several collecting do, and then measurement's too."""
        return self.envs > 1

    @property
    def slots(self) -> int:
        return self.object_slots if self.object_slots is not None else self.env.objects

    @property
    def env_seed(self) -> int:
        """Seed of the stage's first environment (the others follow it)."""
        return int(np.random.SeedSequence([self.seed, self.stage]).generate_state(1)[0])

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "env": self.env.to_dict(), "holdout": self.holdout.to_dict()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainSettings:
        return cls(
            **{
                **data,
                "env": EnvSettings(**data["env"]),
                "buffer": BufferSettings(**data["buffer"]),
                "holdout": Holdout.from_dict(data.get("holdout")),
            }
        )


def pick_device(requested: str | None) -> torch.device:
    """The device asked for (``cpu``, ``cuda`` or ``cuda:N``), by default cuda if available, else cpu.

    Any request this machine cannot serve is a ValueError that says why, never torch's own error from
    deep inside a run: a name torch does not know, a device type lanro does not run on, CUDA where there
    is none, or a CUDA index beyond the devices there are.
    """
    if requested is None:
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    check_device(requested)
    device = torch.device(requested)
    if device.type == "cuda":
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if count == 0:
            raise ValueError(f"--device {requested} was asked for, but torch sees no CUDA device on this machine")
        if device.index is not None and device.index >= count:
            raise ValueError(f"--device {requested} was asked for, but this machine has CUDA devices 0 to {count - 1}")
    return device


def load_policy(path: Path, device: str | torch.device = "cpu") -> tuple[TrainSettings, AgentPolicy]:
    """The settings a checkpoint was trained with and its deterministic policy; ``path`` is a checkpoint,
    a pointer file or a run folder. Raises CheckpointError, ValueError or KeyError on a bad checkpoint."""
    contents = load_checkpoint(resolve_checkpoint(path), device, resumable=False)
    agent = SACAgent.from_state_dict(contents.agent, torch.device(device))
    vocabulary = agent_vocabulary(contents.vocabulary, agent.vocab_size)
    return TrainSettings.from_dict(contents.train_settings), AgentPolicy(agent, vocabulary)


@dataclass
class Progress:
    """Counters of a run; part of every checkpoint."""

    env_steps: int = 0
    episodes: int = 0
    updates: int = 0
    evaluations: int = 0
    train_successes: list[bool] = field(default_factory=list)


class Trainer:
    """Collects, learns and evaluates on one stage's environments; saves and loads all of its state.

    Agent, replay buffer, sampling generator and counters outlive a stage: :meth:`enter_stage` only
    changes what the environments are and how batches are sampled, which is how a curriculum moves on.
    """

    def __init__(
        self,
        settings: TrainSettings,
        agent_settings: SACSettings,
        device: str | torch.device = "cpu",
        vocabulary: Vocabulary | None = None,
    ) -> None:
        """``vocabulary``: the agent's, when it exists already (a resumed run); a new agent reads the
        grammar's."""
        self.settings = settings
        self.agent_settings = agent_settings
        self.device = torch.device(device)
        self.vocabulary = vocabulary if vocabulary is not None else grammar_vocabulary(settings.sentence_corrections)
        obs_dim = observation_size(settings.slots)
        action_dim = action_size(task_class(settings.task).gripper)
        layout = ObjectLayout(ARM_SIZE, OBJECT_SIZE, settings.slots)
        self.agent = SACAgent(
            obs_dim, action_dim, len(self.vocabulary), agent_settings, settings.seed, self.device, layout
        )
        self.buffer = ReplayBuffer(
            settings.buffer.size,
            obs_dim,
            action_dim,
            max_objects=settings.slots,
            vocabulary=self.vocabulary,
            negations=settings.env.negations or settings.buffer.relabel_negations,
            seed=settings.seed,
            holdout=settings.holdout,
        )
        self.rng = np.random.default_rng(np.random.SeedSequence(settings.seed).spawn(2)[1])
        self.progress = Progress()
        self.last_metrics: dict[str, float] = {}
        self._collector: Collector | None = None
        self._evaluation_envs: list[LanroEnv | EnvWorker] = []
        self._restore: tuple[list[dict[str, Any]], list[dict[str, np.ndarray]]] | None = None
        self._started = time.perf_counter()
        self._wall_before = 0.0
        self.clock = PhaseClock()

    def env_factory(self, evaluation: bool = False) -> Callable[[], LanroEnv]:
        """Builds environments of the current stage, observed through the run's object slots. A plain
        partial, so that subprocesses receive the settings and not the trainer."""
        s = self.settings
        env = s.env.for_evaluation(s.eval_correction_rate) if evaluation else s.env
        return functools.partial(
            LanroEnv, s.task, env, object_slots=s.slots, vocabulary=self.vocabulary, holdout=s.holdout
        )

    def enter_stage(
        self, env: EnvSettings, stage: int, eval_episodes: int, eval_rate: float | None, buffer: BufferSettings
    ) -> None:
        """Collect, sample and evaluate with new settings from now on. The old stage's unfinished episodes are
        dropped: they were collected under a goal distribution that no longer holds, and half an episode gives
        relabelling no future to look at."""
        self.close()
        self._restore = None
        changes = {
            "env": env,
            "stage": stage,
            "eval_episodes": eval_episodes,
            "eval_correction_rate": eval_rate,
            "buffer": buffer,
        }
        self.settings = dataclasses.replace(self.settings, **changes)
        self.buffer.negations = env.negations or self.settings.buffer.relabel_negations

    # -- running -----------------------------------------------------------------------------------------

    def run(
        self,
        until: int,
        should_stop: Callable[[], bool] = lambda: False,
        on_step: Callable[[Trainer], None] | None = None,
    ) -> bool:
        """Collect and learn until ``until`` environment steps in total; False if ``should_stop`` ended it
        early (checked before every step)."""
        s = self.settings
        collector = self._ensure_collector()
        while self.progress.env_steps < until:
            if should_stop():
                return False
            step_started = time.perf_counter()
            actions = self.agent.act(collector.observation)
            collector.step_async(actions)
            n = updates_due(self.progress.env_steps, s.envs, s.updates_per_step)
            if self.buffer.size >= max(s.learning_starts, 1) and n > 0:
                learn_started = time.perf_counter()
                self.last_metrics = self.agent.learn(self.buffer, self.rng, n, s.buffer)
                self.progress.updates += n
                self.clock.update_s += time.perf_counter() - learn_started
                self.clock.updates += n
                step_started += time.perf_counter() - learn_started  # the rest of the step is collection
            for episode in collector.step_wait():
                self.buffer.add_episode(episode.data)
                self.agent.update_normalizer(episode.data.observations)
                self.progress.episodes += 1
                self.progress.train_successes.append(episode.success)
                del self.progress.train_successes[:-SUCCESS_WINDOW]
            self.progress.env_steps += s.envs
            self.clock.collection_s += time.perf_counter() - step_started
            if on_step is not None:
                on_step(self)
        return True

    def _ensure_collector(self) -> Collector:
        if self._collector is None:
            s = self.settings
            snapshots, partials = self._restore if self._restore is not None else (None, None)
            self._collector = Collector(self.env_factory(), s.envs, s.task, s.env_seed, restore=snapshots)
            if partials is not None:
                self._collector.restore_partials(partials)
            self._restore = None
        return self._collector

    def evaluate(self, first_seed: int, episodes: int | None = None) -> EvaluationReport:
        """The deterministic policy on evaluation episodes; episode i is reset with ``first_seed + i``. The
        environments are built once per stage: building one costs as much as a few episodes."""
        if not self._evaluation_envs:
            self._evaluation_envs = make_envs(self.env_factory(evaluation=True), SIDE_BY_SIDE, self.settings.in_workers)
        started = time.perf_counter()
        policy = AgentPolicy(self.agent, self.vocabulary)
        report = evaluate(self._evaluation_envs, policy, episodes or self.settings.eval_episodes, first_seed)
        self.clock.evaluation_s += time.perf_counter() - started
        self.clock.evaluation_steps += sum(result.length for result in report.results)
        return report

    @property
    def train_success(self) -> float | None:
        """Success over the last training episodes (stochastic policy), or None before the first one ends."""
        successes = self.progress.train_successes
        return float(np.mean(successes)) if successes else None

    def wall_time(self) -> float:
        """Seconds of training so far, over every resumed part of the run."""
        return self._wall_before + time.perf_counter() - self._started

    # -- checkpoints -------------------------------------------------------------------------------------

    def save(self, directory: Path, extra: Mapping[str, Any] | None = None, resumable: bool = True) -> Path:
        """Write a checkpoint at ``directory`` (which must not exist). ``extra``: plain data of the caller's
        (a curriculum's position) stored beside the trainer's. A checkpoint that is not ``resumable`` holds
        the agent and the settings only: enough to evaluate, a fraction of the size."""
        contents = Checkpoint(
            agent=self.agent.state_dict(),
            train_settings=self.settings.to_dict(),
            vocabulary=self.vocabulary.to_dict(),
            progress=dataclasses.asdict(self.progress),
            rng=self.rng.bit_generator.state,
            wall_time=self.wall_time(),
            extra=dict(extra or {}),
            clock=self.clock.to_dict(),
        )
        if resumable:
            collector = self._ensure_collector()
            contents = dataclasses.replace(
                contents, buffer=self.buffer, partials=collector.partials(), environments=collector.snapshots()
            )
        return save_checkpoint(directory, contents)

    @classmethod
    def load(cls, directory: Path, device: str | torch.device = "cpu") -> tuple[Trainer, dict[str, Any]]:
        """The trainer exactly as a resumable checkpoint left it, and the caller's ``extra`` data."""
        contents = load_checkpoint(directory, device)
        try:
            vocabulary = agent_vocabulary(contents.vocabulary, contents.agent["vocab_size"])
        except ValueError as error:
            raise CheckpointError(f"{directory}: {error}") from None
        trainer = cls(TrainSettings.from_dict(contents.train_settings), contents.agent_settings, device, vocabulary)
        trainer.agent.load_state_dict(contents.agent)
        trainer.buffer = contents.buffer
        trainer.progress = Progress(**contents.progress)
        trainer.rng.bit_generator.state = contents.rng
        trainer._wall_before = contents.wall_time
        trainer.clock = PhaseClock.from_dict(contents.clock)
        trainer._restore = (contents.environments, contents.partials)
        return trainer, contents.extra

    def close(self) -> None:
        if self._collector is not None:
            self._collector.close()
            self._collector = None
        for env in self._evaluation_envs:
            env.close()
        self._evaluation_envs = []
