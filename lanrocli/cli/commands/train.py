"""``lanro check`` and ``lanro train``: a curriculum checked and shown, or run in its run folder, started or
resumed. A bad curriculum is refused before torch and pybullet load."""

from __future__ import annotations

import os
import shlex
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from lanrocli.cli.arguments import CURRICULUM_HELP, SETTINGS, device_option, err_console, fail, load_plan
from lanrocli.cli.display.commands import print_finished_run, print_packaged, print_plan


def check_command(
    curriculum: Annotated[
        str | None,
        typer.Argument(
            metavar="CURRICULUM",
            help=f"Curriculum to validate: {CURRICULUM_HELP}. Without one, the packaged curricula are listed; with "
            "--quick, the built-in one is checked.",
        ),
    ] = None,
    quick: Annotated[
        bool,
        typer.Option(
            "--quick",
            help="Show the plan 'lanro train --quick' runs: the built-in curriculum as written, or FILE scaled down.",
        ),
    ] = False,
    changes: Annotated[
        list[str] | None,
        typer.Option(
            "--set", metavar=SETTINGS, help="KEY=VALUE changed in the plan shown, as 'lanro train --set' does."
        ),
    ] = None,
) -> None:
    """Validate a curriculum and print the resolved plan (stages, budgets, total steps) without training."""
    if curriculum is None and not quick:
        if changes:
            raise fail("--set needs the curriculum it applies to")
        print_packaged()
        return
    plan = load_plan(curriculum, quick, None, None, changes or [])
    print_plan(plan)


def train_command(
    curriculum: Annotated[
        str | None,
        typer.Argument(
            metavar="CURRICULUM",
            help=f"{CURRICULUM_HELP} ('lanro check' lists them). Optional with --quick (the built-in "
            "curricula/quick.yaml) and with --resume.",
        ),
    ] = None,
    out: Annotated[Path | None, typer.Option(help="Run folder (default: checkpoints/<curriculum name>).")] = None,
    seed: Annotated[int | None, typer.Option(min=0, help="Override the curriculum's seed.")] = None,
    envs: Annotated[
        int | None, typer.Option(min=1, max=64, help="Override the number of parallel environments.")
    ] = None,
    device: Annotated[
        str | None, typer.Option(callback=device_option, help="cpu, cuda or cuda:N (default: cuda if available).")
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            min=1,
            max=256,
            help="Processes that measure each stage's agents (default: the cores this process may use). The "
            "figures do not depend on it; a run may resume with another.",
        ),
    ] = None,
    resume: Annotated[bool, typer.Option("--resume", help="Continue the run in --out where it stopped.")] = False,
    source: Annotated[
        Path | None,
        typer.Option(
            "--from",
            metavar="RUN",
            help="Begin where the run in RUN ended the stage before the first in which its curriculum and this one "
            "differ (they may differ in their stages alone, or add stages after RUN's last): its earlier stages are "
            "copied, not trained again.",
        ),
    ] = None,
    quick: Annotated[
        bool,
        typer.Option(
            "--quick",
            help="Without a file: the built-in curriculum (curricula/quick.yaml), a run of a few minutes that "
            "learns. With a file: that file with every budget and evaluation scaled down, to try it out.",
        ),
    ] = False,
    changes: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar=SETTINGS,
            help="KEY=VALUE changed in the curriculum, by its key paths as its error messages name them, the value "
            "read as YAML: agent.critics=2 'stages[0].budget.steps=5000'.",
        ),
    ] = None,
) -> None:
    """Train an agent through a curriculum of stages, with evaluation, checkpoints and resume."""
    if curriculum is None and not quick and not resume:
        raise fail(
            "give a curriculum (a YAML file, or a packaged one by name: 'lanro check' lists them), or --quick "
            "for the built-in one"
        )
    if source is not None and (resume or curriculum is None and not quick):
        raise fail("--from starts a new run from another run's stages: give the curriculum to run, without --resume")
    if curriculum is None and not quick and changes:
        raise fail("--set needs the curriculum it applies to; a resumed run keeps the settings it started with")
    plan = None if curriculum is None and resume and not quick else load_plan(curriculum, quick, seed, envs, changes)

    # Only now: a bad curriculum is refused without waiting for torch and pybullet to load.
    import torch

    from lanrocli.cli.display.training import TrainingDisplay
    from lanrocli.config.curriculum import CurriculumError
    from lanrocli.evaluation.blocks import MeasuringError
    from lanrocli.train.branch import branch
    from lanrocli.train.checkpoint import CheckpointWriteError
    from lanrocli.train.errors import RunError
    from lanrocli.train.pipeline import CurriculumRun
    from lanrocli.train.stop import StopRequest
    from lanrocli.train.trainer import pick_device

    if out is None:
        if plan is None:
            raise fail("--resume without a curriculum file needs --out: the run folder to continue")
        out = Path("checkpoints") / plan.name
    try:
        torch_device = pick_device(device)
    except ValueError as error:
        raise fail(str(error)) from None
    torch.set_num_threads(1 if torch_device.type == "cpu" else torch.get_num_threads())
    display = TrainingDisplay.for_terminal()
    try:
        if resume:
            run = CurriculumRun.resume(out, plan, torch_device, display)
        elif source is not None:
            assert plan is not None
            run = branch(plan, source, out, torch_device, display)
        else:
            assert plan is not None
            run = CurriculumRun.start(plan, out, torch_device, display)
    except (RunError, CurriculumError) as error:
        raise fail(str(error)) from None
    run.workers = workers or len(os.sched_getaffinity(0))
    for note in run.notes:
        err_console.print(f"[bold yellow]note:[/] {escape(note)}")
    already = run.state.finished  # then running it only completes tests that a stop or a kill interrupted
    again = [
        *([curriculum] if curriculum else []),
        *(["--quick"] if quick else []),
        *(["--seed", str(seed)] if seed is not None else []),
        *(["--envs", str(envs)] if envs is not None else []),
        *(arg for change in changes or [] for arg in ("--set", change)),
    ]
    resume_hint = shlex.join(["lanro", "train", *again]) + f" --out {out} --resume"
    with StopRequest() as stop:
        try:
            with display:
                finished = run.run(should_stop=stop.requested)
        except CheckpointWriteError as error:
            raise fail(f"{error}\nresume with: {resume_hint}", code=1) from None
        except MeasuringError as error:
            raise fail(
                f"{error}. The stage's checkpoint is whole, and a resumed run tests its agents again: {resume_hint}",
                code=1,
            ) from None
        except OSError as error:
            raise fail(
                f"the run stopped: {error}. Its newest checkpoint is whole; "
                f"fix the cause and resume with: {resume_hint}",
                code=1,
            ) from None
        finally:
            run.close()
    console = display.console
    if not finished:
        console.print(f"stopped at {run.trainer.progress.env_steps:,} environment steps; checkpoint written.")
        console.print(f"resume with: {resume_hint}")
        raise typer.Exit(130)
    if already:
        console.print(f"the run in {out} has finished already; see {out / 'report.md'}")
        return
    print_finished_run(console, out)
