"""``lanro sweep``: a curriculum over seeds, settings and grids of settings, one ordinary run folder per
trial, on Ray (:mod:`lanrocli.sweep.driver`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from lanrocli.cli.arguments import CURRICULUM_HELP, SETTINGS, fail, load_plan

if TYPE_CHECKING:
    from lanrocli.config.curriculum import Curriculum
    from lanrocli.sweep.plan import Trial


def sweep_command(
    curriculum: Annotated[
        str | None,
        typer.Argument(
            metavar="CURRICULUM",
            help=f"{CURRICULUM_HELP}. Optional with --quick (the built-in one) and with --resume.",
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(help="Sweep folder: sweep.yaml and one run folder per trial (default: sweeps/<name>)."),
    ] = None,
    seeds: Annotated[
        list[str] | None,
        typer.Option(
            "--seeds", metavar="SEED ...", help="Seeds, each a trial: --seeds 0 1 2 (default: the curriculum's)."
        ),
    ] = None,
    changes: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            metavar=SETTINGS,
            help="KEY=VALUE changed for every trial, by the curriculum's key paths: agent.critics=2.",
        ),
    ] = None,
    grid: Annotated[
        list[str] | None,
        typer.Option(
            "--grid",
            metavar="KEY=V1,V2 ...",
            help="KEY=V1,V2: one trial per combination of the grid's values, times the seeds: "
            "stages[0].budget.steps=50000,100000.",
        ),
    ] = None,
    quick: Annotated[
        bool, typer.Option("--quick", help="As for 'lanro train': every trial scaled down, or the built-in curriculum.")
    ] = False,
    resume: Annotated[
        bool,
        typer.Option("--resume", help="Continue the sweep in --out: unfinished trials from their checkpoints."),
    ] = False,
    address: Annotated[
        str | None,
        typer.Option(
            help="A running Ray cluster to use: auto, or ray://HOST:PORT (default: a local Ray instance, started "
            "and stopped here). Every node must see --out at the same path."
        ),
    ] = None,
    cpus_per_trial: Annotated[
        float,
        typer.Option(
            min=0.01,
            help="CPUs per trial: one for its learner's thread, whose environment workers mostly wait for it "
            "(benchmarks/side_by_side.py measures how many trainings a machine holds).",
        ),
    ] = 1.0,
    gpus_per_trial: Annotated[
        float, typer.Option(min=0, help="GPUs per trial; above 0 the trials train on cuda.")
    ] = 0.0,
    max_concurrent: Annotated[
        int | None,
        typer.Option(min=1, help="Trials at once (default: as many as the CPUs allow, 2 on two cores)."),
    ] = None,
) -> None:
    """Run a curriculum over seeds, settings and grids of settings on Ray: one ordinary run folder per trial."""
    out, trials = _open_sweep(curriculum, out, seeds or [], changes or [], grid or [], quick, resume)
    try:
        from lanrocli.sweep.driver import run_trials
    except ImportError as error:
        raise fail(f"lanro sweep runs on Ray, which is not installed ({error}): pip install -e '.[sweep]'") from None
    from lanrocli.sweep.display import print_outcome, resume_command

    try:
        console, outcome = run_trials(out, trials, cpus_per_trial, gpus_per_trial, max_concurrent, address)
    except KeyboardInterrupt:
        raise fail(
            f"aborted: running trials ended without a checkpoint of this moment; resume with: {resume_command(out)}",
            130,
        ) from None
    code = print_outcome(console, outcome.statuses, outcome.errors, out)
    if code:
        raise typer.Exit(code)


def _open_sweep(
    curriculum: str | None,
    out: Path | None,
    seeds: list[str],
    changes: list[str],
    grid: list[str],
    quick: bool,
    resume: bool,
) -> tuple[Path, list[tuple[Trial, Curriculum]]]:
    """The sweep folder and every trial of the sweep, new or resumed, each trial checked before the folder is
    touched; every problem is a clear error."""
    from lanrocli.config.curriculum import CurriculumError
    from lanrocli.config.overrides import SettingError
    from lanrocli.sweep import plan as sweeps

    spec = None
    if curriculum is not None or quick:
        base = load_plan(curriculum, quick, None, None)
        try:
            spec = sweeps.SweepSpec.from_options(
                base, str(curriculum or "curricula/quick.yaml"), quick, seeds, changes, grid
            )
        except (sweeps.SweepError, SettingError) as error:
            raise fail(str(error)) from None
    elif not resume:
        raise fail(
            "give a curriculum (a YAML file, or a packaged one by name: 'lanro check' lists them), --quick for "
            "the built-in one, or --resume"
        )
    elif seeds or changes or grid:
        raise fail("--seeds, --set and --grid need the curriculum file they apply to")
    if out is None:
        if spec is None:
            raise fail("--resume without a curriculum file needs --out: the sweep folder to continue")
        out = Path("sweeps") / spec.plan["name"]
    try:
        trials = spec.resolve() if spec is not None else None
        spec = sweeps.open_sweep(out, spec, resume)
        return out, trials or spec.resolve()
    except CurriculumError as error:
        count = len(error.problems)
        raise fail(f"{count} problem{'s' if count > 1 else ''} in the sweep's curricula:\n{error}") from None
    except sweeps.SweepError as error:
        raise fail(str(error)) from None
