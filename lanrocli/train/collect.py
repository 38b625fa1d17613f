"""Data collection with gymnasium's vector API, whole episodes at a time, and restorable mid-episode.

Each environment is wrapped in :class:`TrainingEnv`, which (1) reduces ``info`` to flat, fixed-type
entries the vector API can stack, and (2) remembers the random state its current episode began with and
the actions taken since. A checkpoint stores those; a resumed run rebuilds the environment exactly where
it was by resetting with that state and replaying the actions (PyBullet is deterministic), so a resumed
run continues the same episodes instead of starting new ones.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv

from lanrocli.agent.buffer.transitions import EpisodeData
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.workers import kill_at_exit, leave_signals_to_parent
from lanrocli.language import ObjectProps
from lanrocli.train.checkpoint import state_from_json, state_to_json


@dataclass(frozen=True)
class EnvSnapshot:
    """Enough to rebuild one environment mid-episode: the random state at its reset and the actions since."""

    start_state: dict[str, Any]
    actions: list[list[float]]

    def to_dict(self) -> dict[str, Any]:
        return {"start_state": state_to_json(self.start_state), "actions": self.actions}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EnvSnapshot:
        return cls(state_from_json(data["start_state"]), [list(map(float, a)) for a in data["actions"]])


class TrainingEnv(gym.Wrapper):
    """A ``LanroEnv`` that can be snapshotted and restored, with an ``info`` the vector API stacks cleanly."""

    def __init__(self, env: LanroEnv, restore: EnvSnapshot | None = None) -> None:
        super().__init__(env)
        self._restore = restore
        self._start_state: dict[str, Any] = {}
        self._actions: list[list[float]] = []
        self._objects = np.zeros((0, 2), dtype=np.int64)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):  # type: ignore[override]
        if self._restore is not None:
            snapshot, self._restore = self._restore, None
            return self._replay(snapshot)
        if seed is not None:
            self.unwrapped.np_random, _ = seeding.np_random(seed)
        self._start_state = dict(self.unwrapped.np_random.bit_generator.state)
        self._actions = []
        obs, info = self.env.reset(options=options)
        return obs, self._flat_reset(info)

    def step(self, action: np.ndarray):  # type: ignore[override]
        self._actions.append(np.asarray(action, dtype=np.float64).tolist())
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, self._flat(info)

    def snapshot(self) -> dict[str, Any]:
        return EnvSnapshot(self._start_state, list(self._actions)).to_dict()

    def _replay(self, snapshot: EnvSnapshot) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        rng = np.random.Generator(np.random.PCG64())
        rng.bit_generator.state = snapshot.start_state
        self.unwrapped.np_random = rng
        self._start_state = dict(snapshot.start_state)
        self._actions = []
        obs, info = self.env.reset()
        flat = self._flat_reset(info)
        for action in snapshot.actions:
            obs, _, _, _, flat = self.step(np.asarray(action))
        return obs, flat

    def _flat_reset(self, info: dict[str, Any]) -> dict[str, Any]:
        """The objects stay the same all episode, and the vector API stacks arrays: they travel as their
        indices, computed once per episode."""
        self._objects = np.array([o.indices for o in info["objects"]], dtype=np.int64)
        return self._flat(info)

    def _flat(self, info: dict[str, Any]) -> dict[str, Any]:
        return {
            "achieved": np.asarray(info["achieved"], dtype=bool),
            "goal_index": int(info["goal_index"]),
            "correction_episode": info["challenge"] is not None,
            "objects": self._objects,
            "is_success": bool(info["is_success"]),
        }


@dataclass
class _Partial:
    """The steps of one environment's episode so far."""

    goal_index: int
    objects: tuple[ObjectProps, ...]
    correction_episode: bool
    observations: list[np.ndarray] = field(default_factory=list)
    instructions: list[np.ndarray] = field(default_factory=list)
    next_observations: list[np.ndarray] = field(default_factory=list)
    next_instructions: list[np.ndarray] = field(default_factory=list)
    actions: list[np.ndarray] = field(default_factory=list)
    rewards: list[float] = field(default_factory=list)
    terminated: list[bool] = field(default_factory=list)
    achieved: list[np.ndarray] = field(default_factory=list)

    def episode(self, task: str) -> EpisodeData:
        return EpisodeData(
            observations=np.stack(self.observations),
            next_observations=np.stack(self.next_observations),
            instructions=np.stack(self.instructions),
            next_instructions=np.stack(self.next_instructions),
            actions=np.stack(self.actions).astype(np.float32),
            rewards=np.asarray(self.rewards, dtype=np.float32),
            terminated=np.asarray(self.terminated, dtype=bool),
            achieved=np.stack(self.achieved),
            goal_index=self.goal_index,
            objects=self.objects,
            task=task,
            correction_episode=self.correction_episode,
        )


@dataclass(frozen=True)
class FinishedEpisode:
    data: EpisodeData
    success: bool


class Collector:
    """Steps N environments together and hands back each episode once it is complete.

    One environment runs in this process; several run in subprocesses, each stepping while the agent
    learns (``step_async`` / ``step_wait``). Autoreset is SAME_STEP, so the observation that ended an
    episode arrives in ``info["final_obs"]`` and no transition ever spans two episodes.
    """

    def __init__(
        self,
        make_env: Callable[[], LanroEnv],
        n_envs: int,
        task: str,
        seed: int,
        restore: list[dict[str, Any]] | None = None,
    ) -> None:
        snapshots = [EnvSnapshot.from_dict(s) for s in restore] if restore else [None] * n_envs
        if len(snapshots) != n_envs:
            raise ValueError(f"the checkpoint holds {len(snapshots)} environments, not {n_envs}")
        in_subprocess = n_envs > 1
        fns = [self._factory(make_env, snapshot, in_subprocess) for snapshot in snapshots]
        vector_cls = AsyncVectorEnv if in_subprocess else SyncVectorEnv
        self.envs = vector_cls(fns, autoreset_mode=AutoresetMode.SAME_STEP)
        if isinstance(self.envs, AsyncVectorEnv):
            kill_at_exit(self, list(self.envs.processes))
        self.n_envs = n_envs
        self.task = task
        self._obs, info = self.envs.reset(seed=[seed + i for i in range(n_envs)])
        self._partials = [self._new_partial(info, i) for i in range(n_envs)]

    @staticmethod
    def _factory(
        make_env: Callable[[], LanroEnv], snapshot: EnvSnapshot | None, in_subprocess: bool
    ) -> Callable[[], TrainingEnv]:
        def build() -> TrainingEnv:
            # The workers leave a stop request to the main process, which writes a checkpoint that needs
            # them alive. (The vector env also builds one environment in the main process, to read its
            # spaces: that one must keep its signals.)
            parent = multiprocessing.parent_process()
            if in_subprocess and parent is not None and parent.pid is not None:
                leave_signals_to_parent(parent.pid)
            return TrainingEnv(make_env(), snapshot)

        return build

    @staticmethod
    def _new_partial(info: dict[str, Any], i: int) -> _Partial:
        objects = tuple(ObjectProps.from_indices(colour, shape) for colour, shape in info["objects"][i])
        return _Partial(
            goal_index=int(info["goal_index"][i]),
            objects=objects,
            correction_episode=bool(info["correction_episode"][i]),
        )

    @property
    def observation(self) -> dict[str, np.ndarray]:
        return self._obs

    def restore_partials(self, partials: list[dict[str, np.ndarray]]) -> None:
        """Put back the steps each environment's current episode had when the checkpoint was written."""
        for i, data in enumerate(partials):
            p = self._partials[i]
            for key in (
                "observations",
                "instructions",
                "next_observations",
                "next_instructions",
                "actions",
                "achieved",
            ):
                setattr(p, key, list(data[key]))
            p.rewards = list(map(float, data["rewards"]))
            p.terminated = list(map(bool, data["terminated"]))

    def partials(self) -> list[dict[str, np.ndarray]]:
        """Each environment's unfinished episode as arrays, for the checkpoint."""
        obs_dim = self._obs["observation"].shape[1]
        length = self._obs["instruction"].shape[1]
        action_dim = int(np.prod(self.envs.single_action_space.shape))
        out = []
        for p in self._partials:
            t = len(p.actions)

            def rows(values: list, dtype: type, *shape: int) -> np.ndarray:
                return np.array(values, dtype=dtype).reshape(t, *shape)  # noqa: B023 - called within this iteration

            out.append(
                {
                    "observations": rows(p.observations, np.float32, obs_dim),
                    "instructions": rows(p.instructions, np.int64, length),
                    "next_observations": rows(p.next_observations, np.float32, obs_dim),
                    "next_instructions": rows(p.next_instructions, np.int64, length),
                    "actions": rows(p.actions, np.float32, action_dim),
                    "rewards": rows(p.rewards, np.float32),
                    "terminated": rows(p.terminated, bool),
                    "achieved": rows(p.achieved, bool, len(p.objects)),
                }
            )
        return out

    def snapshots(self) -> list[dict[str, Any]]:
        return list(self.envs.call("snapshot"))

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions
        if isinstance(self.envs, AsyncVectorEnv):
            self.envs.step_async(actions)

    def step_wait(self) -> list[FinishedEpisode]:
        if isinstance(self.envs, AsyncVectorEnv):
            obs, rewards, terminated, truncated, info = self.envs.step_wait()
        else:
            obs, rewards, terminated, truncated, info = self.envs.step(self._actions)
        finished: list[FinishedEpisode] = []
        for i in range(self.n_envs):
            ended = bool(terminated[i] or truncated[i])
            step_info = info["final_info"] if ended else info
            next_obs = info["final_obs"][i] if ended else {k: v[i] for k, v in obs.items()}
            p = self._partials[i]
            p.observations.append(self._obs["observation"][i])
            p.instructions.append(self._obs["instruction"][i])
            p.next_observations.append(next_obs["observation"])
            p.next_instructions.append(next_obs["instruction"])
            p.actions.append(np.array(self._actions[i], dtype=np.float32))
            p.rewards.append(float(rewards[i]))
            p.terminated.append(bool(terminated[i]))
            p.achieved.append(np.asarray(step_info["achieved"][i], dtype=bool))
            if ended:
                finished.append(FinishedEpisode(p.episode(self.task), bool(step_info["is_success"][i])))
                self._partials[i] = self._new_partial(info, i)
        self._obs = obs
        return finished

    def close(self) -> None:
        self.envs.close()
