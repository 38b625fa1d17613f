"""Episodes played in blocks over worker processes: how a run measures its agents and how the benchmark
scores a policy.

Measuring is simulation and small forward passes, one core's work per episode, so it spreads over cores by
episodes: each worker plays a contiguous block of :data:`CHUNK` of them with a copy of the policy,
``SIDE_BY_SIDE`` at a time, and the results are taken in episode order. One process plays the very same
blocks one after another, so a stopping rule stops at the same episode and every figure is the same for
any number of workers (:func:`_here` says why the blocks must match). The processes are the standard
library's pool, or Ray's workers.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import pickle
import sys
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any

from lanrocli.core.choices import Instruction
from lanrocli.envs.workers import leave_signals_to_parent
from lanrocli.evaluation.adapters import as_policy, load_factory
from lanrocli.evaluation.evaluate import SIDE_BY_SIDE, EvaluationReport
from lanrocli.evaluation.metrics import EpisodeResult
from lanrocli.evaluation.rollout import run_episodes

if TYPE_CHECKING:
    from lanrocli.envs.env import LanroEnv

CHUNK = 50
"""Episodes in one block: enough to pay for building its environments, few enough that a quota is not
overshot by much."""

WAIT_SECONDS = 0.5
"""How often ``progress`` hears from a measurement waiting on its workers."""


class MeasuringError(RuntimeError):
    """A worker process ended in the middle of a block (killed, or out of memory): the measurement's
    episodes are not all there, so none of it is kept."""


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


class _RayFuture:
    def __init__(self, reference: Any) -> None:
        self.reference = reference

    def result(self, timeout: float | None = None) -> Any:
        import ray

        try:
            return ray.get(self.reference, timeout=timeout)
        except ray.exceptions.GetTimeoutError:
            raise TimeoutError from None

    def cancel(self) -> None:
        import ray

        ray.cancel(self.reference)


class Workers:
    """The processes that measurements share: ``count`` of them on this machine (1: this process plays
    every episode itself), or Ray's at ``address``. Open one for many measurements: a worker pays seconds
    to start (torch, pybullet)."""

    def __init__(self, count: int = 1, address: str | None = None) -> None:
        if count < 1:
            raise ValueError(f"workers must be at least 1, got {count}")
        self.count = count
        self.address = address
        self._pool: ProcessPoolExecutor | None = None
        self._remote: Any = None

    @property
    def here(self) -> bool:
        """Whether this process plays the episodes itself."""
        return self.count == 1 and self.address is None

    @property
    def width(self) -> int:
        """How many blocks run at once: the workers, or on Ray at least the cluster's CPUs."""
        if self.address is None:
            return self.count
        import ray

        self._start_ray()
        return max(self.count, int(ray.cluster_resources().get("CPU", 1)))

    def source(self, policy: Any) -> PolicySource:
        """What these workers build ``policy`` from; a ValueError where other processes need a copy of it and
        it does not pickle."""
        if self.here:
            return PolicySource(policy=policy)
        try:
            return PolicySource(pickled=pickle.dumps(policy))
        except Exception as error:
            label = getattr(policy, "name", None) or type(policy).__name__
            raise ValueError(
                f"several workers each need a copy of the policy, and {label} does not pickle ({error}): "
                "measure it with one worker, or give a 'package.module:function' that makes it"
            ) from None

    def submit(self, *args: Any) -> Future[list[EpisodeResult]] | _RayFuture:
        """A block (the arguments of :func:`_play`) started in a worker."""
        if self.address is not None:
            self._start_ray()
            return _RayFuture(self._remote.remote(*args))
        if self._pool is None:
            # spawn, not fork: the workers run torch, whose thread pools do not survive a fork. Ctrl-C and
            # SIGTERM are this process's to act on (a run stops cleanly, then ends the pool), and each worker
            # ends with this process however it ends, so a killed run or scoring leaves nothing running
            self._pool = ProcessPoolExecutor(
                self.count,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=leave_signals_to_parent,
                initargs=(os.getpid(),),
            )
        return self._pool.submit(_play, *args)

    def _start_ray(self) -> None:
        if self._remote is None:
            import ray

            ray.init(address=self.address, ignore_reinit_error=True, log_to_driver=False)
            self._remote = ray.remote(_play)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None

    def __enter__(self) -> Workers:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        self.close()


@functools.lru_cache(maxsize=1)
def _built(pickled: bytes | None, spec: str | None, task: str | None) -> Any:
    """A worker's policy, built once per process from its pickle or spec: it plays many blocks with it."""
    return PolicySource(pickled=pickled, spec=spec, task=task).build()


def _play(
    source: PolicySource,
    make_env: Callable[[], LanroEnv],
    count: int,
    first: int,
    origin: int,
    instruction: Instruction,
) -> list[EpisodeResult]:
    """Episodes ``first`` to ``first + count - 1``, played side by side in a worker."""
    if "torch" in sys.modules:  # the workers share the cores: one thread each, as training's workers
        sys.modules["torch"].set_num_threads(1)
    policy = _built(source.pickled, source.spec, source.task)
    results: list[EpisodeResult] = []
    _block(policy, make_env, count, first, origin, instruction, lambda r: results.append(r) is None)
    return results


def _block(
    policy: Any,
    make_env: Callable[[], LanroEnv],
    count: int,
    first: int,
    origin: int,
    instruction: Instruction,
    on_result: Callable[[EpisodeResult], bool],
) -> None:
    """One block of episodes, in environments built for it: an environment's physics keeps traces of the
    episodes it played before (PyBullet's state is not all reset with the scene), which now and then
    changes an outcome, so every block starts from new ones wherever it is played."""
    envs = [make_env() for _ in range(SIDE_BY_SIDE)]
    try:
        run_episodes(envs, policy, count, first, on_result, instruction, origin=origin)
    finally:
        for env in envs:
            env.close()


def play(
    workers: Workers,
    source: PolicySource,
    make_env: Callable[[], LanroEnv],
    episodes: int,
    first: int,
    instruction: Instruction = Instruction.TRUE,
    enough: Callable[[EvaluationReport], bool] | None = None,
    progress: Callable[[int], None] | None = None,
) -> EvaluationReport:
    """Up to ``episodes`` episodes from seed ``first``, in blocks of :data:`CHUNK` over ``workers``, at most
    twice as many blocks in flight as run at once, taken in episode order until ``enough`` holds.
    ``progress`` hears the episodes taken after each and at least every :data:`WAIT_SECONDS`, and may raise
    to stop the measurement. A worker that dies raises :class:`MeasuringError`. One block's episodes are
    played here: a worker would take longer to start than they take."""
    if workers.here or episodes <= CHUNK:
        return _here(source.build(), make_env, episodes, first, instruction, enough, progress)
    report = EvaluationReport()
    pending: deque[tuple[Any, int, int]] = deque()
    start = 0
    try:
        while True:
            while len(pending) < 2 * workers.width and start < episodes:
                count = min(CHUNK, episodes - start)
                pending.append(
                    (workers.submit(source, make_env, count, first + start, first, instruction), start, count)
                )
                start += count
            if not pending:
                return report
            future, block, count = pending.popleft()
            for result in _waited(future, range(block, block + count), first, progress, len(report.results)):
                report.results.append(result)
                if progress is not None:
                    progress(len(report.results))
                if enough is not None and enough(report):
                    return report
    finally:
        for future, _, _ in pending:
            future.cancel()


def _here(
    policy: Any,
    make_env: Callable[[], LanroEnv],
    episodes: int,
    first: int,
    instruction: Instruction,
    enough: Callable[[EvaluationReport], bool] | None,
    progress: Callable[[int], None] | None,
) -> EvaluationReport:
    """The episodes played in this process, block after block as workers play them. The blocks must be the
    same wherever they are played: a batched network's arithmetic for one episode rounds in the last bits
    by the rows it shares a batch with, and an environment's physics by the episodes it played before
    (:func:`_block`); either now and then changes an outcome."""
    report = EvaluationReport()

    def taken(result: EpisodeResult) -> bool:
        report.results.append(result)
        if progress is not None:
            progress(len(report.results))
        return enough is None or not enough(report)

    for start in range(0, episodes, CHUNK):
        _block(policy, make_env, min(CHUNK, episodes - start), first + start, first, instruction, taken)
        if enough is not None and enough(report):
            break
    return report


def _waited(
    future: Any, block: range, first: int, progress: Callable[[int], None] | None, taken: int
) -> list[EpisodeResult]:
    """The block's results, ``progress`` told of the ``taken`` episodes while they are awaited."""
    while True:
        try:
            return future.result(timeout=WAIT_SECONDS)
        except TimeoutError:
            if progress is not None:
                progress(taken)
        except BrokenProcessPool:
            raise MeasuringError(
                f"a worker process ended while it played episodes {block.start} to {block.stop - 1} (seeds "
                f"{first + block.start} to {first + block.stop - 1}): it was killed, or ran out of memory. "
                "Nothing of this measurement is kept"
            ) from None
