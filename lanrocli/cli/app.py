"""The ``lanro`` command line: the commands of :mod:`lanrocli.cli.commands` under one typer application.

Importing it loads neither torch nor pybullet: each command loads what it needs once its options are read,
so ``lanro --help`` and ``lanro check`` answer at once.
"""

from __future__ import annotations

from typing import Annotated

import typer

from lanrocli import __version__
from lanrocli.cli.commands import evaluate, export, language, play, results, sweep, train
from lanrocli.cli.options import Command, Group

app = typer.Typer(
    name="lanro",
    help="Train and evaluate a simulated Panda arm that follows language instructions and recovers from corrections.",
    no_args_is_help=True,
    cls=Group,
    pretty_exceptions_enable=False,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"lanro {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """Train and evaluate a simulated Panda arm that follows language instructions and recovers from corrections."""


app.command("sample-instructions", cls=Command)(language.sample_instructions)
app.command("eval", cls=Command)(evaluate.evaluate_command)
app.command("check", cls=Command)(train.check_command)
app.command("train", cls=Command)(train.train_command)
app.command("export", cls=Command)(export.export_command)
app.command("plot", cls=Command)(results.plot_command)
app.command("sweep", cls=Command)(sweep.sweep_command)
app.command("report", cls=Command)(results.report_command)
app.command("play", cls=Command)(play.play_command)
