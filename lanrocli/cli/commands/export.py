"""``lanro export``: a trained agent's policy alone, with where it came from, to ship with lanro."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from lanrocli.cli.arguments import fail


def export_command(
    source: Annotated[
        Path, typer.Argument(help="A checkpoint, a pointer such as RUN/stage-3-negations/last, or a run folder.")
    ],
    out: Annotated[
        Path, typer.Option(help="The folder to write, which must not exist (lanrocli/pretrained/NAME to ship it).")
    ],
    commit: Annotated[str, typer.Option(help="The commit the agent was trained at, recorded with it.")],
) -> None:
    """Write a trained agent's policy alone, with where it came from: an agent to ship.

    The folder holds the commit, seed and test figures the agent came from; lanro eval NAME and lanro play
    NAME find the agents in lanrocli/pretrained."""
    from lanrocli.pretrained import export_agent
    from lanrocli.train.errors import CheckpointError

    if out.exists():
        raise fail(f"--out {out} exists; give a new folder")
    try:
        written = export_agent(source, out, commit)
    except (CheckpointError, KeyError, ValueError) as error:
        raise fail(f"cannot export {source}: {error}") from None
    size = sum(f.stat().st_size for f in written.iterdir())
    Console().print(f"wrote {written} ({size / 1e6:.2f} MB)")
