"""The tasks lanro knows: an explicit registry of task classes, from which every list of tasks is read.

The registry keeps the order of registration, which is part of the data: a replay buffer stores each
episode's task as its index here, so the built-in tasks keep their places and a new one comes after them.
``TASKS`` and ``TASK_VERBS`` are live views of it, so a task registered later (a test's toy task) is at once
known to the instructor, the grammar and the scripted policies; ``registered`` takes one back out when its
block ends, so a registration never outlives what needed it.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import overload

from lanrocli.tasks.base import TaskDefinition

_classes: dict[str, type[TaskDefinition]] = {}

REQUIRED = ("name", "gym_id", "verbs")
"""The class attributes a task must set; the rest have defaults in ``TaskDefinition``."""


def register(cls: type[TaskDefinition]) -> type[TaskDefinition]:
    """Add a task class under its ``name``; a name or gymnasium id already taken is refused."""
    missing = [attribute for attribute in REQUIRED if not hasattr(cls, attribute)]
    if missing:
        raise TypeError(f"task class {cls.__name__} does not set {', '.join(missing)}")
    if not cls.verbs:
        raise TypeError(f"task class {cls.__name__} has no verbs: the instructor could not name it")
    for known in _classes.values():
        if cls.name == known.name or cls.gym_id == known.gym_id:
            raise ValueError(f"task {cls.name!r} ({cls.gym_id}) clashes with {known.name!r} ({known.gym_id})")
    _classes[cls.name] = cls
    return cls


def unregister(name: str) -> None:
    """Remove the task ``name``; what was registered before it keeps its place."""
    task_class(name)
    del _classes[name]


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
    if name not in _classes:
        raise ValueError(f"task must be one of {list(_classes)}, got {name!r}")
    return _classes[name]


def make_task(name: str) -> TaskDefinition:
    """A fresh task ``name`` for one environment."""
    return task_class(name)()


def check_task(task: str) -> str:
    """Return ``task`` if it is a known task, else raise a ``ValueError`` that lists the known ones."""
    if task not in _classes:
        raise ValueError(f"unknown task {task!r}; expected one of {', '.join(_classes)}")
    return task


class _Names(Sequence[str]):
    """The registered tasks' names, in registration order."""

    @overload
    def __getitem__(self, index: int) -> str: ...

    @overload
    def __getitem__(self, index: slice) -> Sequence[str]: ...

    def __getitem__(self, index: int | slice) -> str | Sequence[str]:
        return tuple(_classes)[index]

    def __len__(self) -> int:
        return len(_classes)

    def __repr__(self) -> str:
        return repr(tuple(_classes))


class _Verbs(Mapping[str, tuple[str, ...]]):
    """Each registered task's verbs, by name."""

    def __getitem__(self, name: str) -> tuple[str, ...]:
        return _classes[name].verbs

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(_classes))

    def __len__(self) -> int:
        return len(_classes)


TASKS: Sequence[str] = _Names()
"""The names of the registered tasks, in registration order."""

TASK_VERBS: Mapping[str, tuple[str, ...]] = _Verbs()
"""The verbs of each registered task."""
