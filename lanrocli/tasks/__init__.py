"""The tasks: one class each (``lanrocli.tasks.base.TaskDefinition``), and the registry every list of tasks
is read from: the curriculum's and the command line's choices, the gymnasium ids, the instructor's verbs.

The built-in tasks are registered here, in the order whose indices replay buffers store, so a new built-in
task's class goes at the end of ``BUILT_IN`` (docs/architecture.md, "add a task").
"""

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
    "TaskView",
    "check_task",
    "make_task",
    "register",
    "registered",
    "task_class",
    "unregister",
]
