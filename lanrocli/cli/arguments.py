"""How the commands read the command line beyond what typer does: errors that name the option, every
``--device`` checked by name, one option per environment setting generated from ``EnvSettings``, and the
curriculum with its ``--quick`` and ``--set``. Light: nothing here loads torch or pybullet, so a command
refuses a bad option at once."""

from __future__ import annotations

import dataclasses
import inspect
import types
import typing
from collections.abc import Callable
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape

from lanrocli.core.choices import check_device
from lanrocli.envs.settings import EnvSettings

if TYPE_CHECKING:
    from lanrocli.config.curriculum import Curriculum

CURRICULUM_HELP = "A YAML file, or the name of a curriculum that ships with lanro, such as push"

SETTINGS = "KEY=VALUE ..."
"""The metavar of ``--set``: several settings may follow it."""

err_console = Console(stderr=True, soft_wrap=True)


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print ``message`` as an error on stderr and return the exit to raise. The message is escaped, not read
    as rich markup: it quotes files, keys and values, where ``[/x]`` would otherwise raise a MarkupError."""
    err_console.print(f"[bold red]error:[/] {escape(message)}")
    return typer.Exit(code)


def device_option(value: str | None) -> str | None:
    """Every command's ``--device``, checked by name before anything loads, as ``pick_device`` checks it."""
    if value is not None:
        try:
            check_device(value)
        except ValueError as error:
            raise fail(str(error)) from None
    return value


def _without_none(hint: Any) -> Any:
    args = [arg for arg in typing.get_args(hint) if arg is not type(None)]
    return args[0] if typing.get_origin(hint) in (typing.Union, types.UnionType) and len(args) == 1 else hint


def _is_list(hint: Any) -> bool:
    """Whether a setting holds several values, which the command line reads comma-separated."""
    return typing.get_origin(_without_none(hint)) is tuple


def with_env_options(**helps: str) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Give a command one option per ``EnvSettings`` field, from the field's type and ``help`` (or the one
    ``helps`` gives it, where the command reads the setting its own way): typer reads the signature, and the
    command receives them in its ``**env_options``, None where not given. A field whose metadata says
    ``option: False`` is left out: only training's collection acts on it."""

    def add_options(command: Callable[..., None]) -> Callable[..., None]:
        signature = inspect.signature(command, eval_str=True)
        hints = typing.get_type_hints(EnvSettings)
        options = [
            inspect.Parameter(
                f.name,
                inspect.Parameter.KEYWORD_ONLY,
                default=None,
                annotation=Annotated[
                    (str if _is_list(hints[f.name]) else _without_none(hints[f.name])) | None,
                    typer.Option(help=helps.get(f.name, f.metadata["help"])),
                ],
            )
            for f in dataclasses.fields(EnvSettings)
            if f.metadata["option"]
        ]
        kept = [p for p in signature.parameters.values() if p.kind is not inspect.Parameter.VAR_KEYWORD]
        command.__signature__ = signature.replace(parameters=kept + options)  # type: ignore[attr-defined]
        return command

    return add_options


def env_changes(options: dict[str, Any]) -> dict[str, Any]:
    """The environment settings given on the command line, each checked on its own so that a problem names
    its option."""
    hints = typing.get_type_hints(EnvSettings)
    changes = {}
    for name, value in options.items():
        if value is None:
            continue
        if _is_list(hints[name]):
            value = tuple(part.strip() for part in value.split(",") if part.strip())
        try:
            EnvSettings(**{name: value})
        except ValueError as error:
            raise fail(f"--{name.replace('_', '-')}: {error}") from None
        changes[name] = value
    return changes


def load_plan(
    path: str | None, quick: bool, seed: int | None, envs: int | None, changes: list[str] | None = None
) -> Curriculum:
    """The curriculum to run, with the command line's overrides: the file or packaged curriculum ``path``
    names, scaled down by ``quick`` (to try a file out); without one, with ``quick``, the built-in
    curriculum exactly as written (``curricula/quick.yaml``, whose budgets are small already). Then the
    ``--set`` settings ``changes``, so that they win over the scaling."""
    from lanrocli.config.curriculum import CurriculumError, builtin_curriculum, find_curriculum, load_curriculum
    from lanrocli.config.overrides import SettingError, read_settings

    try:
        settings = read_settings("--set", changes or [])
        plan = load_curriculum(find_curriculum(path)) if path is not None else builtin_curriculum()
        if quick and path is not None:
            plan = plan.quick()
        if settings:
            plan = plan.with_settings(settings, path or "curricula/quick.yaml")
    except SettingError as error:
        raise fail(str(error)) from None
    except CurriculumError as error:
        count = len(error.problems)
        raise fail(f"{count} problem{'s' if count > 1 else ''} in the curriculum:\n{error}") from None
    return plan.with_overrides(seed=seed, envs=envs)
