"""How the ``lanro`` commands read and show their options beyond what typer does by itself."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import typer
from typer.core import TyperCommand, TyperGroup, TyperOption


class _FlagsUnlabelled:
    """A flag takes no value, so its help shows no type; typer would label each one ``<bool>``. Its
    parameters are read here, where help and parsing get them, since typer adds some after the command is
    made (``--help``, shell completion); an empty metavar is what typer shows in the label's place."""

    def get_params(self, ctx: typer.Context) -> list[Any]:
        params: list[Any] = super().get_params(ctx)  # type: ignore[misc]
        for param in params:
            if isinstance(param, TyperOption) and param.is_flag:
                param.metavar = ""
        return params


class Command(_FlagsUnlabelled, TyperCommand):
    """Every ``lanro`` command. ``--seeds 0 1 2`` and ``--set a=1 b=2`` take several values after one option,
    as well as the usual ``--seeds 0 --seeds 1``: each further value is read as if the option stood before it
    again, so a shell's list of settings needs no option repeated."""

    MANY: ClassVar[dict[str, Callable[[str], bool]]] = {
        "--seeds": lambda text: text.replace(",", "").isdigit(),
        "--set": lambda text: "=" in text,
        "--grid": lambda text: "=" in text,
    }

    def parse_args(self, ctx: typer.Context, args: list[str]) -> list[str]:
        spread: list[str] = []
        option, own_value = None, False
        for arg in args:
            if own_value:
                spread.append(arg)
                own_value = False
            elif option is not None and not arg.startswith("-") and self.MANY[option](arg):
                spread += [option, arg]
            else:
                option = arg if arg in self.MANY else None
                own_value = option is not None
                spread.append(arg)
        return super().parse_args(ctx, spread)


class Group(_FlagsUnlabelled, TyperGroup):
    """``lanro`` itself: its flags (``--version``, shell completion, ``--help``) show no type either."""
