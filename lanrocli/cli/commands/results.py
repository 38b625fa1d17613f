"""``lanro plot`` and ``lanro report``: the runs and sweeps that have been made, drawn and aggregated."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from lanrocli.cli.arguments import fail


def plot_command(
    runs: Annotated[
        list[Path],
        typer.Argument(
            help="Run folders or sweep folders: the seeds of one setting are drawn as their mean with a 95% bootstrap "
            "band, one line per setting."
        ),
    ],
    out: Annotated[Path, typer.Option(help="Image to write (.png, .svg or .pdf).")] = Path("curves.png"),
    title: Annotated[str | None, typer.Option(help="Figure title (default: the folder names).")] = None,
) -> None:
    """Plot success against environment steps, overall and on correction episodes, with stage boundaries."""
    from lanrocli.report.groups import group_runs
    from lanrocli.report.plot import plot_groups

    try:
        groups = [(group.label, group.runs) for group in group_runs(runs)]
        path = plot_groups(groups, out, title or ", ".join(run.name for run in runs))
    except (FileNotFoundError, ValueError) as error:
        raise fail(str(error)) from None
    Console().print(f"wrote {path}")


def report_command(
    runs: Annotated[list[Path], typer.Argument(help="Run folders or sweep folders.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object on stdout.")] = False,
    out: Annotated[Path | None, typer.Option(help="Also write the report as Markdown here.")] = None,
    agent: Annotated[str, typer.Option(help="Which agent of each stage: last or best.")] = "last",
) -> None:
    """Aggregate runs and sweeps per task and stage, with bootstrap intervals over runs.

    For each stage: the steps it took, and its agent's test figures (success, corrected, per kind and form of
    correction; for the last stage also its correction test) as the mean over runs with a 95% stratified
    bootstrap interval, and the interquartile mean from five runs on; a kind or form some run heard too few
    times to judge is marked *. Runs that differ in their settings are grouped and compared side by side.
    """
    from lanrocli.report.aggregate import ReportError, make_report
    from lanrocli.report.output import to_json, to_markdown

    if agent not in ("last", "best"):
        raise fail("--agent is last or best")
    try:
        report = make_report(runs, agent)
    except ReportError as error:
        raise fail(str(error)) from None
    text = to_markdown(report)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
    if as_json:
        typer.echo(json.dumps(to_json(report)))
        return
    console = Console()
    if console.is_terminal:
        from rich.markdown import Markdown

        console.print(Markdown(text))
    else:
        typer.echo(text, nl=False)
