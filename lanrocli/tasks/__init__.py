"""The tasks: one class each (``lanrocli.tasks.base.TaskDefinition``), and the registry every list of tasks
is read from: the curriculum's and the command line's choices, the gymnasium ids, the instructor's verbs.

The built-in tasks are registered here, in the order whose indices replay buffers store, so a new built-in
task's class goes at the end of ``BUILT_IN`` (docs/architecture.md, "add a task").
"""

from enum import StrEnum

from lanrocli.tasks.base import FALLEN, ArmView, OracleMemory, TaskDefinition, TaskView
from lanrocli.tasks.grasp import Grasp
from lanrocli.tasks.lift import Lift
from lanrocli.tasks.push import Push
from lanrocli.tasks.reach import Reach
from lanrocli.tasks.registry import (
    TASK_VERBS,
    TASKS,
    check_task,
    make_task,
    register,
    registered,
    task_class,
    unregister,
)

BUILT_IN: tuple[type[TaskDefinition], ...] = (Reach, Push, Grasp, Lift)

for _task in BUILT_IN:
    register(_task)

Task = StrEnum("Task", [(name.upper(), name) for name in TASKS], module=__name__)
"""The names of the tasks registered in ``lanrocli.tasks`` when this module loads (the built-in ones), in
their order: what the curriculum schema (pydantic) and the command line (typer) accept. What a task is and
does belongs to its class, ``lanrocli.tasks.task_class(name)``."""

__all__ = [
    "BUILT_IN",
    "FALLEN",
    "TASKS",
    "TASK_VERBS",
    "ArmView",
    "Grasp",
    "Lift",
    "OracleMemory",
    "Push",
    "Reach",
    "TaskDefinition",
    "Task",
    "TaskView",
    "check_task",
    "make_task",
    "register",
    "registered",
    "task_class",
    "unregister",
]
