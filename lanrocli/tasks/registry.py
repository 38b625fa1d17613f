"""The tasks lanro knows: the registry of task classes, from which every list of tasks is read.

The registry keeps the order of registration, which is part of the data: a replay buffer stores each
episode's task as its index here, so the built-in tasks keep their places and a new one comes after them.
``TASKS`` and ``TASK_VERBS`` are live views of it, so a task registered later (a test's toy task) is at once
known to the instructor, the grammar and the scripted policies; ``registered`` takes one back out when its
block ends, so a registration never outlives what needed it.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager

from lanrocli.core.registry import Registry
from lanrocli.tasks.base import TaskDefinition

REQUIRED = ("name", "gym_id", "verbs")
"""The class attributes a task must set; the rest have defaults in ``TaskDefinition``."""

_TASK_CLASSES: Registry[type[TaskDefinition]] = Registry("task", lambda cls: cls.name)


def register(cls: type[TaskDefinition]) -> type[TaskDefinition]:
    """Add a task class under its ``name``; a class without a name, id or verbs, or whose name or gymnasium
    id is taken, is refused."""
    missing = [attribute for attribute in REQUIRED if not hasattr(cls, attribute)]
    if missing:
        raise TypeError(f"task class {cls.__name__} does not set {', '.join(missing)}")
    if not cls.verbs:
        raise TypeError(f"task class {cls.__name__} has no verbs: the instructor could not name it")
    for known in _TASK_CLASSES:
        if cls.gym_id == known.gym_id and cls.name != known.name:
            raise ValueError(f"task {cls.name!r} has the gymnasium id {cls.gym_id} of task {known.name!r}")
    return _TASK_CLASSES.register(cls)


def unregister(name: str) -> None:
    """Remove the task ``name``; the tasks registered before and after it keep their order."""
    _TASK_CLASSES.unregister(name)


@contextmanager
def registered(cls: type[TaskDefinition]) -> Iterator[type[TaskDefinition]]:
    """``cls`` registered for the ``with`` block only."""
    register(cls)
    try:
        yield cls
    finally:
        unregister(cls.name)


def task_class(name: str) -> type[TaskDefinition]:
    """The class of task ``name``, or a ``ValueError`` that lists the known tasks."""
    return _TASK_CLASSES.named(name)


def make_task(name: str) -> TaskDefinition:
    """A fresh task ``name`` for one environment."""
    return task_class(name)()


def check_task(task: str) -> str:
    """Return ``task`` if it is a known task, else raise a ``ValueError`` that lists the known ones."""
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; expected one of {', '.join(TASKS)}")
    return task


class _Verbs(Mapping[str, tuple[str, ...]]):
    """Each registered task's verbs, by name."""

    def __getitem__(self, name: str) -> tuple[str, ...]:
        return _TASK_CLASSES.by_name[name].verbs

    def __iter__(self) -> Iterator[str]:
        return iter(TASKS)

    def __len__(self) -> int:
        return len(_TASK_CLASSES)


TASKS: Sequence[str] = _TASK_CLASSES.names
"""The names of the registered tasks, in registration order."""

TASK_VERBS: Mapping[str, tuple[str, ...]] = _Verbs()
"""The verbs of each registered task."""
