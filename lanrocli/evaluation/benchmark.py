"""Score any policy on a benchmark protocol (:mod:`lanrocli.evaluation.protocols`): ``lanrocli.evaluate``.

A policy is whatever answers an observation with an action, in one of four shapes, tried in this order:
an object with ``act_batch(observations) -> (actions, attention or None)`` (lanro's agents), one with
``act(observation, info)`` and optionally ``reset(seed)`` (lanro's scripted policies), a stable-baselines3
model or policy (anything with ``predict(observation, deterministic=True)``), or a plain function
``f(observation, info) -> action``. ``info`` is the environment's: the episode's sentence as text
(``instruction_text``), the objects, the correction spoken; the observation holds the sentence as token ids.

The record is the one ``lanro eval --json`` prints, with the protocol's name and version beside it. The
episodes may run in several processes, or on a Ray cluster: each runs a contiguous block of them, and the
results are taken in episode order, so a run stopped by a quota stops at the same episode as one process
would, and every figure is the same (:func:`~lanrocli.evaluation.rollout._decide` pads batches so that a
network computes each episode's actions alike wherever it runs).
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import multiprocessing
import os
import pickle
import sys
from collections import deque
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from lanrocli.config.curriculum import load_curriculum, packaged_curricula
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.settings import EnvSettings
from lanrocli.envs.workers import exit_with_parent
from lanrocli.evaluation.evaluate import SIDE_BY_SIDE, EvaluationReport
from lanrocli.evaluation.metrics import EpisodeResult
from lanrocli.evaluation.protocols import PROTOCOL_VERSION, TEST_EPISODES, Protocol, find_protocol, first_seed
from lanrocli.evaluation.quota import CorrectionQuota
from lanrocli.evaluation.rollout import run_episodes
from lanrocli.evaluation.splits import CONTROL, DROP, paired_drops
from lanrocli.language import Vocabulary, grammar_vocabulary
from lanrocli.tasks import TASKS

CHUNK = 50
"""Episodes one worker plays at a time: enough to pay for building its environments, few enough that a
quota is not overshot by much."""


class PredictPolicy:
    """A stable-baselines3 model (or anything with its ``predict``) as a batch policy, acting deterministically."""

    def __init__(self, model: Any) -> None:
        self.model = model

    def act_batch(self, observations: dict[str, np.ndarray]) -> tuple[np.ndarray, None]:
        actions, _ = self.model.predict(observations, deterministic=True)
        return np.asarray(actions), None


class FunctionPolicy:
    """A function ``f(observation, info) -> action`` as a policy without state."""

    def __init__(self, function: Callable[[dict[str, np.ndarray], dict[str, Any]], Any]) -> None:
        self.function = function

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> Any:
        return self.function(observation, info)


def as_policy(policy: Any) -> Any:
    """``policy`` in a shape the rollout drives (module docstring), or a TypeError that says what is missing."""
    if hasattr(policy, "act_batch") or hasattr(policy, "act"):
        return policy
    if hasattr(policy, "predict"):
        return PredictPolicy(policy)
    if callable(policy):
        return FunctionPolicy(policy)
    raise TypeError(
        f"{policy!r} is not a policy: give a function f(observation, info) -> action, an object with "
        "act(observation, info), or a stable-baselines3 model"
    )


def load_factory(spec: str) -> Callable[[str], Any]:
    """The function ``spec`` names, ``package.module:function`` or ``path/to/file.py:function``, which
    makes a policy for a task's name; a ValueError that says what went wrong."""
    module_name, _, attribute = spec.rpartition(":")
    if not module_name or not attribute:
        raise ValueError(f"{spec!r} names no function: write package.module:make_policy or file.py:make_policy")
    try:
        if module_name.endswith(".py"):
            path = Path(module_name).resolve()
            if not path.is_file():
                raise ValueError(f"{spec!r}: there is no file {path}")
            loader = importlib.util.spec_from_file_location(path.stem, path)
            assert loader is not None and loader.loader is not None
            module = importlib.util.module_from_spec(loader)
            sys.modules[loader.name] = module  # as an import would: dataclasses and pickles look it up there
            loader.loader.exec_module(module)
        else:
            if "" not in sys.path:  # a module beside the command line's folder, as `python -m` finds it
                sys.path.insert(0, "")
            module = importlib.import_module(module_name)
    except ValueError:
        raise
    except Exception as error:
        raise ValueError(f"cannot import {module_name!r} for {spec!r}: {type(error).__name__}: {error}") from error
    factory = getattr(module, attribute, None)
    if not callable(factory):
        raise ValueError(f"{spec!r}: {module_name} has no function {attribute!r}")
    return factory


@dataclass(frozen=True)
class PolicySource:
    """What a worker builds its policy from: the policy itself (in this process), its pickle, or a
    factory's ``spec`` that each worker imports and calls for ``task``. A policy goes to other processes as
    bytes of the standard pickle: handed to them as an object, its tensors would travel as handles to this
    process's shared memory, which a worker may open only after this process has let them go."""

    policy: Any = None
    pickled: bytes | None = None
    spec: str | None = None
    task: str | None = None

    def build(self) -> Any:
        if self.spec is not None:
            return as_policy(load_factory(self.spec)(self.task))
        if self.pickled is not None:
            return as_policy(pickle.loads(self.pickled))
        return as_policy(self.policy)


def protocol_env(task: str, chosen: Protocol, vocabulary: Vocabulary | None = None) -> functools.partial[LanroEnv]:
    """What builds the environments of ``chosen`` on ``task``: its packaged curriculum's last stage as
    evaluation sees it, changed by the protocol, with the curriculum's holdout and object slots; the
    sentences encoded by ``vocabulary`` (a trained agent's), else by the grammar's."""
    packaged = packaged_curricula()
    if task not in packaged or task not in TASKS:
        tasks = ", ".join(t for t in TASKS if t in packaged)
        raise ValueError(f"the benchmark plays the tasks with a curriculum of their name ({tasks}), not {task!r}")
    curriculum = load_curriculum(packaged[task])
    stage = curriculum.stages[-1].env.settings().for_evaluation()
    grammar = grammar_vocabulary(curriculum.max_corrections)
    if vocabulary is not None and vocabulary.max_length != grammar.max_length:
        # the sentence's length decides which paraphrases fit, so every policy must read the same one
        raise ValueError(
            f"the benchmark's sentences have {grammar.max_length} words at most, and this agent reads "
            f"{vocabulary.max_length}: score an agent trained on {task}'s curriculum (its max_corrections)"
        )
    return functools.partial(
        LanroEnv,
        curriculum.task,
        stage.replace(**chosen.changes(stage)),
        object_slots=curriculum.max_objects,
        vocabulary=vocabulary or grammar,
        holdout=curriculum.holdout.settings(),
        split=chosen.split,
    )


@functools.lru_cache(maxsize=1)
def _built(pickled: bytes | None, spec: str | None, task: str | None) -> Any:
    """A worker's policy, built once per process from its pickle or spec: it plays many blocks with it."""
    return PolicySource(pickled=pickled, spec=spec, task=task).build()


def _play(
    source: PolicySource, make_env: Callable[[], LanroEnv], count: int, first: int, origin: int, protocol_name: str
) -> list[EpisodeResult]:
    """Episodes ``first`` to ``first + count - 1`` of a protocol, played side by side in this process."""
    chosen = find_protocol(protocol_name)
    policy = as_policy(source.policy) if source.policy is not None else _built(source.pickled, source.spec, source.task)
    if "torch" in sys.modules:  # the workers share the cores: one thread each, as training's workers
        sys.modules["torch"].set_num_threads(1)
    envs = [make_env() for _ in range(SIDE_BY_SIDE)]
    results: list[EpisodeResult] = []
    try:
        run_episodes(envs, policy, count, first, lambda r: results.append(r) is None, chosen.instruction, origin=origin)
    finally:
        for env in envs:
            env.close()
    return results


class _Later:
    """Work for this process, done when its result is asked for: one process plays no block it then drops."""

    def __init__(self, function: Callable[..., Any], *args: Any) -> None:
        self.call = functools.partial(function, *args)

    def result(self) -> Any:
        return self.call()

    def cancel(self) -> None:
        pass


class _RayFuture:
    def __init__(self, reference: Any) -> None:
        self.reference = reference

    def result(self) -> Any:
        import ray

        return ray.get(self.reference)

    def cancel(self) -> None:
        import ray

        ray.cancel(self.reference)


def _executor(workers: int, address: str | None) -> tuple[Callable[..., Any], Callable[[], None], int]:
    """A ``submit(function, *args) -> future`` for ``workers`` processes here, or Ray at ``address``; the
    call that ends it; and how many blocks run at once (on Ray, at least the cluster's CPUs)."""
    if address is not None:
        import ray

        ray.init(address=address, ignore_reinit_error=True, log_to_driver=False)
        remote = ray.remote(_play)
        width = max(workers, int(ray.cluster_resources().get("CPU", 1)))
        return lambda _, *args: _RayFuture(remote.remote(*args)), lambda: None, width
    if workers == 1:
        return _Later, lambda: None, 1
    # spawn, not fork: the workers run torch, whose thread pools do not survive a fork; each ends with this
    # process however it ends, so a killed scoring leaves nothing running
    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(workers, mp_context=context, initializer=exit_with_parent, initargs=(os.getpid(),))
    return pool.submit, lambda: pool.shutdown(wait=False, cancel_futures=True), workers


def play(
    source: PolicySource,
    make_env: Callable[[], LanroEnv],
    episodes: int,
    first: int,
    chosen: Protocol,
    enough: Callable[[EvaluationReport], bool] | None = None,
    workers: int = 1,
    address: str | None = None,
) -> EvaluationReport:
    """Up to ``episodes`` episodes from seed ``first``, in blocks of :data:`CHUNK` over ``workers`` processes
    (or Ray at ``address``), at most twice as many blocks in flight as workers; taken in episode order
    until ``enough`` holds."""
    submit, end, width = _executor(workers, address)
    report = EvaluationReport()
    pending: deque[Any] = deque()
    start = 0
    try:
        while True:
            while len(pending) < 2 * width and start < episodes:
                count = min(CHUNK, episodes - start)
                pending.append(submit(_play, source, make_env, count, first + start, first, chosen.name))
                start += count
            if not pending:
                return report
            for result in pending.popleft().result():
                report.results.append(result)
                if enough is not None and enough(report):
                    return report
    finally:
        for future in pending:
            future.cancel()
        end()


def _met(quota: CorrectionQuota, report: EvaluationReport, negations: bool) -> bool:
    return quota.met(report, negations)


def _label(policy: Any) -> str:
    return getattr(policy, "name", None) or type(policy).__name__


def evaluate(policy: Any, task: str, protocol: str = "test", **options: Any) -> dict[str, Any]:
    """Score ``policy`` (module docstring), or the policy a ``package.module:function`` spec makes for the
    task, on ``task``'s ``protocol`` (``PROTOCOLS``) and return its record: what ``lanro eval --json``
    prints, and under ``benchmark`` the protocol, its version and the first seed. ``episodes`` plays fewer
    or more (for the correction test: caps them), which the record says (``complete``); ``workers``
    processes share the episodes, or Ray's workers at ``address`` (``auto`` or ``ray://host:port``). With
    several workers the policy must pickle, or come as a spec. A policy that raises or answers with no
    action fails with a :class:`~lanrocli.evaluation.rollout.PolicyError` that names the episode."""
    return score(policy, task, protocol, **options)[1]


def score(
    policy: Any,
    task: str,
    protocol_name: str = "test",
    *,
    episodes: int | None = None,
    workers: int = 1,
    address: str | None = None,
    label: str | None = None,
) -> tuple[EvaluationReport, dict[str, Any]]:
    """:func:`evaluate`'s report and record (``options`` are these keywords), for the command line, which
    prints the report as a table."""
    chosen = find_protocol(protocol_name)
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    if episodes is not None and episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    if isinstance(policy, str):
        source = PolicySource(spec=policy, task=task)
        built = source.build()
    else:
        built = as_policy(policy)
        source = PolicySource(policy=policy)
        if workers > 1 or address is not None:
            try:
                source = PolicySource(pickled=pickle.dumps(policy))
            except Exception as error:
                raise ValueError(
                    f"several workers each need a copy of the policy, and {_label(policy)} does not pickle "
                    f"({error}): score it with workers=1, or give a 'package.module:function' that makes it"
                ) from None
    vocabulary = getattr(built, "vocabulary", None)
    make_env = protocol_env(task, chosen, vocabulary if isinstance(vocabulary, Vocabulary) else None)
    env_settings: EnvSettings = make_env.args[1]
    first = first_seed(task, chosen)
    quota = chosen.quota
    if quota is not None:
        quota = replace(quota, episodes=episodes or quota.episodes)
        count = quota.episodes
        enough: Callable[[EvaluationReport], bool] | None = functools.partial(
            _met, quota, negations=env_settings.negations
        )
    else:
        count, enough = episodes or TEST_EPISODES, None
    played = functools.partial(
        play, source, episodes=count, first=first, chosen=chosen, workers=workers, address=address
    )
    report = played(make_env, enough=enough)
    record: dict[str, Any] = {
        "benchmark": {
            "protocol": chosen.name,
            "version": PROTOCOL_VERSION,
            "first_seed": first,
            "complete": episodes is None or episodes == (chosen.quota.episodes if chosen.quota else TEST_EPISODES),
        },
        "policy": label or (policy if isinstance(policy, str) else _label(policy)),
        "task": task,
        "env": env_settings.to_dict(),
        "instruction": chosen.instruction.value,
        **report.as_dict(),
    }
    if quota is not None:
        record["quota"] = {**asdict(quota), "negations": quota.negations if env_settings.negations else 0}
        record["quota_met"] = quota.met(report, env_settings.negations)
    if chosen.split is not None:
        record["split"] = chosen.split.value
    if chosen.controlled:
        control = played(functools.partial(make_env, split=None))
        record[CONTROL] = control.as_dict()
        record[DROP] = paired_drops(chosen.split, report.results, control.results)  # type: ignore[arg-type]
    return report, record
