"""The gymnasium ids of the tasks, registered whenever ``lanrocli`` is imported.

Registration names the environment class by an import string, so it loads neither pybullet nor the
environment module: they load when an environment is made. ``import lanrocli`` therefore stays cheap
enough for every command of the CLI, and ``gymnasium.make("lanro/Push-v0")`` works after it.

``gymnasium.make`` keeps its ``max_episode_steps`` keyword to itself: it wraps the environment in a
``TimeLimit`` with that limit, or with the spec's when none is given, and never passes it on. So the specs
carry the default settings' limit, and the environments they make leave counting steps to that wrapper
(``time_limit=False``): the limit asked of ``make`` is the one an episode is truncated at.

Gymnasium 1.0 dropped the discovery of environments through package entry points, so an interpreter
that has not imported lanrocli finds the ids by naming the package in the id, which gymnasium imports
first: ``gymnasium.make("lanrocli:lanro/Push-v0")``.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from lanrocli.envs.settings import EnvSettings
from lanrocli.tasks import TASKS, task_class

ENV_IDS: dict[str, str] = {name: task_class(name).gym_id for name in TASKS}
"""The gymnasium id of each task registered when lanrocli is imported (the built-in ones), as each task's
class gives it."""

ENTRY_POINT = "lanrocli.envs.env:LanroEnv"


def register_envs() -> None:
    """Register the id of every task in ``lanrocli.tasks`` that gymnasium does not know yet.

    Ids already known are left alone, so running it again (a reload of the package, a caller that
    registers explicitly, or one that registered a task of its own first) changes nothing and gives
    gymnasium no override to warn about.
    """
    for task in TASKS:
        env_id = task_class(task).gym_id
        if env_id not in registry:
            register(
                id=env_id,
                entry_point=ENTRY_POINT,
                max_episode_steps=EnvSettings().episode_limit,
                kwargs={"task": task, "time_limit": False},
            )
