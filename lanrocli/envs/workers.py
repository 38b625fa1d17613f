"""Environments in processes of their own, for evaluation and tests.

Measuring an agent is mostly simulation: the policy answers the episodes side by side in one batch, but
each episode's physics is one core's work. An :class:`EnvWorker` steps its environment in a subprocess, so
the episodes of one batch simulate on as many cores as the machine has. It answers the calls
:mod:`lanrocli.evaluation.rollout` makes of an environment (``reset``, ``step``, ``render``) with the values the
environment itself returns, and adds ``step_async`` / ``step_wait`` so the rollout can set every episode
stepping before it waits for the first. PyBullet is deterministic, so an episode played in a worker is the
one played in this process, step for step.
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.util
import os
import signal
import threading
import time
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Any

import numpy as np

from lanrocli.tasks import make_task

if TYPE_CHECKING:
    from lanrocli.envs.env import LanroEnv

PARENT_CHECK_SECONDS = 0.5

StepResult = tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]


def exit_with_parent(parent: int) -> None:
    """End this process soon after process ``parent`` ends, however it ends (a SIGKILL included), so a
    killed trainer leaves no environment worker behind: a watcher thread sees this process handed to
    another parent and exits at once."""

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_SECONDS)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def leave_signals_to_parent(parent: int) -> None:
    """Ctrl-C in a terminal, or a scheduler's SIGTERM, reaches the whole process group. A worker leaves it
    to the main process, which stops cleanly and may still need the worker; if the main process dies
    without closing it, the worker exits on its own."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    exit_with_parent(parent)


def kill_at_exit(owner: object, processes: list[multiprocessing.Process]) -> None:
    """Kill ``processes`` when ``owner`` is collected or, at the latest, as this interpreter exits.

    multiprocessing ends daemon children at exit with SIGTERM and then waits for them; workers ignore
    SIGTERM (:func:`leave_signals_to_parent`), so a script that never closed its environments would wait at
    exit for ever. This runs first (multiprocessing's finalisers run before it ends children), and killing
    is safe: a worker holds nothing to save. After a ``close`` it finds nothing left to kill."""
    multiprocessing.util.Finalize(owner, _kill, args=(processes,), exitpriority=0)


def _kill(processes: list[multiprocessing.Process]) -> None:
    for process in processes:
        if process.is_alive():
            process.kill()


class WorkerError(RuntimeError):
    """An environment call failed in a worker; the message carries the worker's traceback."""


def _serve(connection: Connection, make_env: Callable[[], LanroEnv], parent: int) -> None:
    leave_signals_to_parent(parent)
    try:
        env = make_env()
    except Exception:  # the parent re-raises it with the worker's traceback
        connection.send(("error", traceback.format_exc()))
        return
    connection.send(("ok", (env.task.name, env.vocabulary, env.metadata, env.render_mode, env.action_space)))
    calls: dict[str, Callable[[Any], Any]] = {
        "reset": lambda seed: env.reset(seed=seed),
        "step": env.step,
        "render": lambda _: env.render(),
    }
    while True:
        name, argument = connection.recv()
        if name == "close":
            env.close()
            connection.close()
            return
        try:
            reply = calls[name](argument)
        except Exception:
            connection.send(("error", traceback.format_exc()))
        else:
            connection.send(("ok", reply))


class EnvWorker:
    """One environment, built by ``make_env`` (which must pickle: a partial of ``LanroEnv``) in a
    subprocess, and driven from this one."""

    def __init__(self, make_env: Callable[[], LanroEnv]) -> None:
        context = multiprocessing.get_context()
        self._connection, child = context.Pipe()
        self._process = context.Process(target=_serve, args=(child, make_env, os.getpid()), daemon=True)
        self._process.start()
        kill_at_exit(self, [self._process])
        child.close()
        self._pending = False

    def wait_ready(self) -> EnvWorker:
        """Wait until the environment is built and take its description: separate from ``__init__`` so
        that several workers build theirs at once."""
        task, self.vocabulary, self.metadata, self.render_mode, self.action_space = self._receive()
        self.task = make_task(task)
        return self

    def reset(self, *, seed: int) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        return self._call("reset", seed)

    def step_async(self, action: np.ndarray) -> None:
        self._connection.send(("step", action))
        self._pending = True

    def step_wait(self) -> StepResult:
        self._pending = False
        return self._receive()

    def step(self, action: np.ndarray) -> StepResult:
        self.step_async(action)
        return self.step_wait()

    def render(self) -> np.ndarray | None:
        return self._call("render", None)

    def close(self) -> None:
        """Ends the worker; safe to call twice, and after the worker has died."""
        if self._process.is_alive():
            try:
                if self._pending:
                    self._connection.recv()
                self._connection.send(("close", None))
            except (BrokenPipeError, EOFError, OSError):
                pass
            self._process.join(timeout=5)
            if self._process.is_alive():
                self._process.kill()
        self._connection.close()

    def _call(self, name: str, argument: Any) -> Any:
        self._connection.send((name, argument))
        return self._receive()

    def _receive(self) -> Any:
        try:
            status, payload = self._connection.recv()
        except EOFError:
            raise WorkerError(f"the environment worker (pid {self._process.pid}) ended unexpectedly") from None
        if status == "error":
            raise WorkerError(f"the environment worker failed:\n{payload}")
        return payload


def make_envs(make_env: Callable[[], LanroEnv], count: int, in_workers: bool) -> list[Any]:
    """``count`` environments of ``make_env``, each in a worker of its own where ``in_workers``, else in
    this process; close each when done."""
    if not in_workers:
        return [make_env() for _ in range(count)]
    workers: list[EnvWorker] = []
    try:
        workers.extend(EnvWorker(make_env) for _ in range(count))
        return [worker.wait_ready() for worker in workers]
    except BaseException:
        for worker in workers:
            worker.close()
        raise
