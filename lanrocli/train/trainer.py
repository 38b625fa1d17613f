"""One stage of training: collect with N environments, learn, evaluate every K steps, checkpoint.

The trainer owns every piece of state a run has (agent, replay buffer, sampling generator, environments
mid-episode, counters) and can write all of it to a checkpoint and continue from one as if it had never
stopped: on CPU with one environment, N steps straight and N/2 + resume + N/2 give identical parameters.
"""

from __future__ import annotations

import csv
import dataclasses
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lanrocli.agent import ReplayBuffer, SACAgent, SACSettings
from lanrocli.envs import LanroEnv, observation_size
from lanrocli.envs.evaluation import EvaluationReport, evaluate
from lanrocli.language import grammar_vocabulary
from lanrocli.train.checkpoint import (
    LATEST,
    CheckpointError,
    load_checkpoint,
    prune,
    read_pointer,
    save_checkpoint,
    write_pointer,
)
from lanrocli.train.collect import Collector, state_from_json, state_to_json

EVAL_SEED = 1_000_000
"""Evaluation episodes use seeds from here on, apart from any training seed."""

SUCCESS_WINDOW = 100
"""Training episodes over which the reported training success is averaged."""

CHECKPOINTS = "checkpoints"
METRICS = "metrics.csv"


@dataclass(frozen=True)
class TrainSettings:
    """What one training run needs besides the agent's own settings."""

    task: str = "reach"
    env: Mapping[str, Any] = field(default_factory=dict)
    """Keyword arguments of ``LanroEnv`` besides the task (objects, mode, correction_rate, ...)."""
    seed: int = 0
    envs: int = 1
    eval_every: int = 5000
    eval_episodes: int = 20
    learning_starts: int = 1000
    """Environment steps collected before the first update."""
    max_objects: int = 3
    """Object slots in the buffer; at least the number of objects of any stage."""

    def __post_init__(self) -> None:
        if self.envs < 1:
            raise ValueError(f"envs must be at least 1, got {self.envs}")
        if self.eval_every < 1 or self.eval_episodes < 1:
            raise ValueError("eval_every and eval_episodes must be positive")
        if self.learning_starts < 0:
            raise ValueError(f"learning_starts must not be negative, got {self.learning_starts}")

    def to_dict(self) -> dict[str, Any]:
        data = dataclasses.asdict(self)
        data["env"] = dict(self.env)
        return data


def pick_device(requested: str | None) -> torch.device:
    """``cuda`` when asked (an error if there is none), the default is cuda if available, else cpu."""
    if requested is None:
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    device = torch.device(requested)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError("--device cuda was asked for, but torch sees no CUDA device on this machine")
    return device


class AgentPolicy:
    """The agent's deterministic policy in the scripted-policy interface, for evaluation."""

    def __init__(self, agent: SACAgent) -> None:
        self.agent = agent

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        return self.agent.act(observation, deterministic=True)


@dataclass
class Progress:
    """Counters of a run; part of every checkpoint."""

    env_steps: int = 0
    episodes: int = 0
    updates: int = 0
    evaluations: int = 0
    train_successes: list[bool] = field(default_factory=list)


class Trainer:
    def __init__(
        self,
        settings: TrainSettings,
        agent_settings: SACSettings,
        out: Path,
        device: str | torch.device = "cpu",
    ) -> None:
        self.settings = settings
        self.agent_settings = agent_settings
        self.out = out
        self.device = torch.device(device)
        self.vocabulary = grammar_vocabulary()
        probe = self._make_env()
        obs_dim = probe.observation_space["observation"].shape[0]
        action_dim = probe.action_space.shape[0]
        probe.close()
        self.agent = SACAgent(obs_dim, action_dim, len(self.vocabulary), agent_settings, settings.seed, self.device)
        self.buffer = ReplayBuffer(
            agent_settings.buffer_size,
            obs_dim,
            action_dim,
            max_objects=settings.max_objects,
            vocabulary=self.vocabulary,
            negations=bool(settings.env.get("negations", False)),
            seed=settings.seed,
        )
        self.rng = np.random.default_rng(np.random.SeedSequence(settings.seed).spawn(2)[1])
        self.progress = Progress()
        self.last_metrics: dict[str, float] = {}
        self.last_report: EvaluationReport | None = None
        self._collector: Collector | None = None
        self._started = time.perf_counter()
        self._wall_before = 0.0

    def _make_env(self) -> LanroEnv:
        return LanroEnv(self.settings.task, **self.settings.env)

    # -- running -----------------------------------------------------------------------------------------

    def run(
        self,
        until: int,
        should_stop: Callable[[], bool] = lambda: False,
        on_step: Callable[[Trainer], None] | None = None,
        on_evaluation: Callable[[Trainer, EvaluationReport], None] | None = None,
    ) -> bool:
        """Train until ``until`` environment steps in total; returns False if ``should_stop`` ended it early.

        A checkpoint is written after every evaluation and when stopping early.
        """
        s, a = self.settings, self.agent_settings
        if self._collector is None:
            self._collector = Collector(self._make_env, s.envs, s.task, s.seed)
        collector = self._collector
        while self.progress.env_steps < until:
            if should_stop():
                self.checkpoint()
                return False
            actions = self.agent.act(collector.observation)
            collector.step_async(actions)
            if self.buffer.size >= max(s.learning_starts, 1) and a.updates_per_step > 0:
                n = a.updates_per_step * s.envs
                self.last_metrics = self.agent.learn(self.buffer, self.rng, n)
                self.progress.updates += n
            for episode in collector.step_wait():
                self.buffer.add_episode(episode.data)
                self.agent.update_normalizer(episode.data.observations)
                self.progress.episodes += 1
                self.progress.train_successes.append(episode.success)
                del self.progress.train_successes[:-SUCCESS_WINDOW]
            before = self.progress.env_steps
            self.progress.env_steps += s.envs
            if on_step is not None:
                on_step(self)
            if self.progress.env_steps // s.eval_every > before // s.eval_every:
                report = self.evaluate()
                if on_evaluation is not None:
                    on_evaluation(self, report)
                self.checkpoint()
        return True

    def evaluate(self, episodes: int | None = None) -> EvaluationReport:
        env = self._make_env()
        try:
            report = evaluate(env, AgentPolicy(self.agent), episodes or self.settings.eval_episodes, EVAL_SEED)
        finally:
            env.close()
        self.progress.evaluations += 1
        self.last_report = report
        self._log(report)
        return report

    def wall_time(self) -> float:
        return self._wall_before + time.perf_counter() - self._started

    def _log(self, report: EvaluationReport) -> None:
        path = self.out / METRICS
        row = {
            "env_steps": self.progress.env_steps,
            "wall_time": round(self.wall_time(), 2),
            "success": report.overall.success,
            "correction_success": report.corrections.success if report.corrections.episodes else "",
            "mean_return": report.mean_return,
            "train_success": float(np.mean(self.progress.train_successes)) if self.progress.train_successes else "",
            **{k: round(v, 5) for k, v in self.last_metrics.items()},
        }
        self.out.mkdir(parents=True, exist_ok=True)
        new = not path.exists()
        with open(path, "a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(row))
            if new:
                writer.writeheader()
            writer.writerow(row)

    # -- checkpoints -------------------------------------------------------------------------------------

    def checkpoint(self) -> Path:
        assert self._collector is not None
        root = self.out / CHECKPOINTS
        directory = root / f"step-{self.progress.env_steps:010d}"
        if directory.exists():  # already written at this step (an evaluation and a stop coincide)
            return directory
        state = {
            "train_settings": self.settings.to_dict(),
            "vocabulary": self.vocabulary.to_dict(),
            "progress": dataclasses.asdict(self.progress),
            "rng": state_to_json(self.rng.bit_generator.state),
            "environments": self._collector.snapshots(),
            "wall_time": self.wall_time(),
        }
        save_checkpoint(directory, self.agent.state_dict(), self.buffer, state, self._collector.partials())
        write_pointer(self.out / LATEST, f"{CHECKPOINTS}/{directory.name}")
        prune(root, keep={directory})
        return directory

    @classmethod
    def resume(cls, out: Path, device: str | torch.device = "cpu") -> Trainer:
        """The run in ``out``, exactly as its latest checkpoint left it."""
        directory = read_pointer(out / LATEST)
        agent_state, buffer, state, partials = load_checkpoint(directory, device)
        settings = TrainSettings(**state["train_settings"])
        trainer = cls(settings, SACSettings.from_dict(agent_state["settings"]), out, device)
        if trainer.vocabulary.to_dict() != state["vocabulary"]:
            raise CheckpointError(f"{directory} was written with another vocabulary than this version of lanro's")
        trainer.agent.load_state_dict(agent_state)
        trainer.buffer = buffer
        trainer.progress = Progress(**state["progress"])
        trainer.rng.bit_generator.state = state_from_json(state["rng"])
        trainer._wall_before = float(state["wall_time"])
        trainer._collector = Collector(
            trainer._make_env, settings.envs, settings.task, settings.seed, restore=state["environments"]
        )
        trainer._collector.restore_partials(partials)
        return trainer

    def close(self) -> None:
        if self._collector is not None:
            self._collector.close()
            self._collector = None

