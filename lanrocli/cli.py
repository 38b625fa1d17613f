"""The ``lanro`` command line: parses options, calls the package, prints with rich, sets exit codes."""

from __future__ import annotations

import json
import sys
import warnings
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from lanrocli import __version__
from lanrocli.language import all_sentences, grammar_vocabulary, sample_sentence, sentence_stats

if TYPE_CHECKING:
    from lanrocli.envs.evaluation import EvaluationReport, Instruction
    from lanrocli.train.curriculum import Curriculum
    from lanrocli.train.testset import Measurement
    from lanrocli.train.trainer import TrainSettings

app = typer.Typer(
    name="lanro",
    help="Train and evaluate a simulated Panda arm that follows language instructions and recovers from corrections.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


err_console = Console(stderr=True, soft_wrap=True)


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print ``message`` as an error on stderr and return the exit to raise."""
    err_console.print(f"[bold red]error:[/] {message}")
    return typer.Exit(code)


class TaskName(str, Enum):
    reach = "reach"
    push = "push"
    grasp = "grasp"
    lift = "lift"


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


@app.command("sample-instructions")
def sample_instructions(
    task: Annotated[TaskName, typer.Option(help="Task whose verbs the instructor uses.")] = TaskName.reach,
    n: Annotated[int, typer.Option("--n", min=1, help="How many sentences to sample.")] = 10,
    seed: Annotated[int, typer.Option(min=0, help="Random seed; the same seed gives the same sentences.")] = 0,
    corrections: Annotated[bool, typer.Option("--corrections", help="Append a correction to each instruction.")] = False,
    negations: Annotated[bool, typer.Option("--negations", help="Allow the negation beginning ('not the ...').")] = False,
    rare: Annotated[bool, typer.Option("--rare", help="Allow rare colour words in instructions.")] = False,
    enumerate_all: Annotated[
        bool, typer.Option("--all", help="Enumerate every sentence of the grammar instead of sampling.")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON array on stdout.")] = False,
    stats: Annotated[
        bool, typer.Option("--stats", help="Print counts (distinct sentences, vocabulary size, L, per form) only.")
    ] = False,
) -> None:
    """Show sentences the instructor can speak: sampled, or all of them."""
    if negations and not corrections:
        raise typer.BadParameter("--negations only affects corrections; add --corrections", param_hint="--negations")
    if enumerate_all:
        sentences = all_sentences(task.value, corrections, negations, rare)
    else:
        rng = np.random.default_rng(seed)
        sentences = iter([sample_sentence(rng, task.value, corrections, negations, rare) for _ in range(n)])
    vocab = grammar_vocabulary()
    console = Console()

    if stats:
        st = sentence_stats(sentences)
        summary = {
            "task": task.value,
            "sentences": st.sentences,
            "distinct_sentences": st.distinct,
            "vocabulary_size": len(vocab),
            "max_length": vocab.max_length,
            "by_form": st.by_form,
            "by_beginning": st.by_beginning,
        }
        if as_json:
            typer.echo(json.dumps(summary))
            return
        table = Table(title=f"grammar statistics: {task.value}", show_header=False)
        table.add_row("sentences", str(st.sentences))
        table.add_row("distinct sentences", str(st.distinct))
        table.add_row("vocabulary size (with <pad>, <unk>)", str(len(vocab)))
        table.add_row("L (padded length)", str(vocab.max_length))
        for form, count in st.by_form.items():
            table.add_row(f"instruction form {form}", str(count))
        for kind, count in st.by_beginning.items():
            table.add_row(f"correction beginning {kind}", str(count))
        console.print(table)
        return

    if as_json:
        out = sys.stdout
        out.write("[")
        for i, s in enumerate(sentences):
            item = {
                "instruction": s.instruction,
                "correction": s.correction,
                "text": s.text,
                "tokens": vocab.encode(s.text).tolist(),
            }
            out.write(("," if i else "") + "\n" + json.dumps(item))
        out.write("\n]\n")
        return
    if enumerate_all:
        for s in sentences:
            typer.echo(s.text)
        return
    table = Table(title=f"{task.value}: {n} sampled sentences (seed {seed})")
    table.add_column("#", justify="right")
    table.add_column("instruction")
    table.add_column("correction")
    table.add_column("tokens")
    for i, s in enumerate(sentences):
        table.add_row(str(i), s.instruction, s.correction or "", " ".join(map(str, vocab.encode(s.text))))
    console.print(table)


class ModeName(str, Enum):
    color = "color"
    shape = "shape"
    color_shape = "color_shape"


class PolicyName(str, Enum):
    oracle = "oracle"
    mistaken = "mistaken"
    random = "random"


def _percent(rate: float) -> str:
    return "-" if rate != rate else f"{100 * rate:5.1f}%"


def _print_report(report: EvaluationReport, title: str) -> None:
    table = Table(title=title)
    for column in ("episodes", "", "success", "95% CI"):
        table.add_column(column, justify="right" if column != "" else "left")
    rows = [
        ("all episodes", report.overall),
        ("correction episodes", report.correction_episodes),
        ("a correction was spoken (corrected)", report.corrected),
    ]
    corrected = report.corrected_by_kind()
    for kind, rate in report.by_kind().items():
        rows += [(f"  {kind}", rate), (f"    {kind}, correction spoken", corrected[kind])]
    rows += [(f"  correction spoken, {name.replace('_', ' ')}", rate) for name, rate in report.by_negation().items()]
    for name, rate in rows:
        low, high = rate.interval
        ci = "-" if not rate.episodes else f"[{100 * low:.1f}, {100 * high:.1f}]"
        table.add_row(str(rate.episodes), name, _percent(rate.success), ci)
    Console().print(table)
    Console().print(f"mean episode length {report.mean_length:.1f} steps, mean return {report.mean_return:.1f}")


def _env_summary(env: dict[str, object]) -> str:
    parts = [f"{env['objects']} objects", str(env["mode"])]
    if env["correction_rate"]:
        parts.append(f"corrections {env['correction_rate']:g}")
        if env.get("negations"):
            parts.append("negations")
        if env.get("max_delay"):
            parts.append(f"delay <= {env['max_delay']}")
        if env.get("rare_words"):
            parts.append("rare words")
        if env.get("kinds"):
            parts.append("kinds " + ",".join(env["kinds"]))  # type: ignore[arg-type]
    if env.get("random_start"):
        parts.append(f"random starts {env['random_start']:g}")
    return ", ".join(parts)


class InstructionName(str, Enum):
    true = "true"
    blank = "blank"
    other = "other"


@app.command("eval")
def evaluate_command(
    what: Annotated[
        str,
        typer.Argument(
            metavar="POLICY_OR_CHECKPOINT",
            help="A scripted policy (oracle, mistaken, random), or a trained agent: a checkpoint directory, a "
            "pointer such as RUN/stage-2-corrections/best, or a run folder (its latest checkpoint).",
        ),
    ],
    task: Annotated[TaskName | None, typer.Option(help="Task (scripted policies; default reach).")] = None,
    objects: Annotated[int | None, typer.Option(min=2, max=3, help="Objects on the table (2 or 3).")] = None,
    mode: Annotated[ModeName | None, typer.Option(help="Which properties vary between objects.")] = None,
    correction_rate: Annotated[
        float | None, typer.Option(min=0.0, max=1.0, help="Share of correction episodes (0 = plain instructions).")
    ] = None,
    negations: Annotated[
        bool | None, typer.Option("--negations/--no-negations", help="Allow negating corrections.")
    ] = None,
    max_delay: Annotated[int | None, typer.Option(min=0, help="Corrections arrive after 0..MAX_DELAY steps.")] = None,
    rare_words: Annotated[
        bool | None, typer.Option("--rare-words/--no-rare-words", help="Allow rare colour words (common ground).")
    ] = None,
    kinds: Annotated[
        str | None,
        typer.Option(help="Comma-separated kinds: ambiguity,common_ground,instruction_correction,wrong_object."),
    ] = None,
    episodes: Annotated[
        int | None,
        typer.Option(min=1, help="Number of episodes (default: a checkpoint's test.episodes, else 100)."),
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option(
            min=0,
            help="Episode i uses seed SEED + i. Default: a checkpoint's held-out test episodes (the ones report.md "
            "quotes), 0 for a scripted policy.",
        ),
    ] = None,
    instruction: Annotated[
        InstructionName,
        typer.Option(
            help="The sentence the agent reads: the instructor's (true), none (blank), or one naming another "
            "object on the table (other; success is the task on that object).",
        ),
    ] = InstructionName.true,
    device: Annotated[str | None, typer.Option(help="cpu or cuda for a trained agent (default: cuda if available).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object on stdout.")] = False,
    gif: Annotated[Path | None, typer.Option(help="Write the first episodes as an animated GIF here.")] = None,
) -> None:
    """Evaluate a scripted policy or a trained agent: success overall, on correction episodes, where a correction
    was spoken, per kind, with 95% intervals. For a checkpoint, the environment defaults to the stage it was
    trained on and the episodes to that stage's held-out test episodes; options change them."""
    from lanrocli.envs import LanroEnv
    from lanrocli.envs.evaluation import Instruction, evaluate
    from lanrocli.envs.policies import make_policy

    given = {
        "objects": objects,
        "mode": None if mode is None else mode.value,
        "correction_rate": correction_rate,
        "negations": negations,
        "max_delay": max_delay,
        "rare_words": rare_words,
        "kinds": None if kinds is None else [k.strip() for k in kinds.split(",") if k.strip()],
    }
    overrides = {k: v for k, v in given.items() if v is not None}
    shown = Instruction(instruction.value)
    if what in {p.value for p in PolicyName}:
        if shown is not Instruction.TRUE:
            raise fail("--instruction changes what a trained agent reads; scripted policies read no sentence")
        task_name = (task or TaskName.reach).value
        env_settings = {"objects": 2, "mode": "color", "correction_rate": 0.0, **overrides}
        first = 0 if seed is None else seed
        try:
            env = LanroEnv(task=task_name, render_mode="rgb_array" if gif else None, **env_settings)
        except ValueError as error:
            raise fail(f"{error} (see 'lanro eval --help')") from None
        try:
            report = evaluate(env, make_policy(what, task_name), episodes or 100, first, gif)
        finally:
            env.close()
        record = {"policy": what, "task": task_name, "env": env_settings, **report.as_dict()}
        where = f"seed {first}"
    else:
        measurement = _measure_checkpoint(Path(what), task, overrides, episodes, seed, shown, device, gif)
        report, record, task_name, env_settings = (
            measurement.report, measurement.record, measurement.settings.task, measurement.env
        )
        where = "held-out test episodes" if measurement.held_out else f"seed {measurement.first_seed}"
        if shown is not Instruction.TRUE:
            where += f", instruction {shown.value}"
    if as_json:
        typer.echo(json.dumps(record))
        return
    summary = _env_summary({"mode": "color", "correction_rate": 0.0, **env_settings})
    _print_report(report, f"{what} on {task_name}, {summary}, {where}")
    if gif:
        Console().print(f"wrote {gif}")


def _measure_checkpoint(
    path: Path,
    task: TaskName | None,
    overrides: dict[str, object],
    episodes: int | None,
    seed: int | None,
    shown: Instruction,
    device: str | None,
    gif: Path | None,
) -> Measurement:
    """The trained agent at ``path`` measured as ``lanro eval`` was asked; every problem is a clear error."""
    from lanrocli.train import CheckpointError, pick_device
    from lanrocli.train.testset import measure

    if not path.exists():
        raise fail(f"{path} is neither a scripted policy (oracle, mistaken, random) nor an existing checkpoint path")

    def check(settings: TrainSettings, env_settings: dict[str, object]) -> None:
        if task is not None and task.value != settings.task:
            raise fail(f"{path} was trained on {settings.task}; it cannot be evaluated on {task.value}")
        if int(env_settings.get("objects", 2)) > settings.slots:  # type: ignore[call-overload]
            raise fail(f"{path} observes at most {settings.slots} objects; --objects must not exceed that")

    try:
        torch_device = pick_device(device)
        count = episodes or _test_episodes(path)
        return measure(path, count, torch_device, overrides, seed, shown, gif, check=check)
    except (CheckpointError, KeyError) as error:
        raise fail(f"cannot load a trained agent from {path}: {error}") from None
    except ValueError as error:
        raise fail(f"{error} (see 'lanro eval --help')") from None


def _test_episodes(path: Path) -> int:
    """The test-set size of the run that ``path`` belongs to, so ``lanro eval`` repeats what report.md quotes."""
    from lanrocli.train.checkpoint import resolve_checkpoint
    from lanrocli.train.curriculum import Curriculum, CurriculumError, HeldOutConfig, load_curriculum
    from lanrocli.train.pipeline import CONFIG

    config = resolve_checkpoint(path).parent.parent / CONFIG
    try:
        plan: Curriculum = load_curriculum(config)
        return plan.test.episodes
    except CurriculumError:
        return HeldOutConfig().episodes


@app.command("check")
def check_command(
    curriculum: Annotated[Path, typer.Argument(help="Curriculum YAML file to validate.")],
    quick: Annotated[bool, typer.Option("--quick", help="Show the plan --quick would run.")] = False,
) -> None:
    """Validate a curriculum and print the resolved plan (stages, budgets, total steps) without training."""
    plan = _load_plan(curriculum, quick, None, None)
    _print_plan(plan)


def _load_plan(path: Path | None, quick: bool, seed: int | None, envs: int | None) -> Curriculum:
    """The curriculum to run: from ``path`` or the built-in one, scaled by --quick, with overrides."""
    from lanrocli.train.curriculum import CurriculumError, builtin_curriculum, load_curriculum

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", FutureWarning)
            plan = load_curriculum(path) if path is not None else builtin_curriculum()
        for warning in caught:
            err_console.print(f"[bold yellow]warning:[/] {path}: {warning.message}")
    except CurriculumError as error:
        count = len(error.problems)
        raise fail(f"{count} problem{'s' if count > 1 else ''} in the curriculum:\n{error}") from None
    if quick:
        plan = plan.quick()
    return plan.with_overrides(seed=seed, envs=envs)


def _print_plan(plan: Curriculum) -> None:
    from lanrocli.agent import SACSettings

    console = Console()
    table = Table(title=f"{plan.name}: {plan.task}, seed {plan.seed}, {plan.envs} environments")
    for column in ("stage", "environment", "budget", "promotion", "when the budget runs out"):
        table.add_column(column)
    for i, stage in enumerate(plan.stages):
        rule = "-"
        if stage.promote is not None:
            p = stage.promote
            measure = "success" if p.statistic == "mean" else "lower end of the 95% interval of success"
            rule = f"{p.on} {measure} >= {p.success:g} on the episodes of {p.patience} evaluation(s) pooled"
        table.add_row(
            f"{i + 1}. {stage.name}",
            _env_summary(stage.env.model_dump()),
            f"{stage.budget.steps:,} steps",
            rule,
            stage.on_budget,
        )
    console.print(table)
    changed = {k: v for k, v in plan.agent.settings().to_dict().items() if SACSettings().to_dict()[k] != v}
    console.print(f"at most {plan.total_steps:,} environment steps in all")
    console.print(
        f"evaluation: {plan.eval.episodes} fresh episodes every {plan.eval.every:,} steps of a stage, and at its end; "
        f"test: {plan.test.episodes} held-out episodes for each stage's last and best agents"
    )
    console.print(f"agent: default settings (SACSettings){', except ' + str(changed) if changed else ''}")


@app.command("train")
def train_command(
    curriculum: Annotated[
        Path | None,
        typer.Argument(help="Curriculum YAML file. Optional with --quick (a built-in one) and with --resume."),
    ] = None,
    out: Annotated[Path | None, typer.Option(help="Run folder (default: checkpoints/<curriculum name>).")] = None,
    seed: Annotated[int | None, typer.Option(min=0, help="Override the curriculum's seed.")] = None,
    envs: Annotated[int | None, typer.Option(min=1, max=64, help="Override the number of parallel environments.")] = None,
    device: Annotated[str | None, typer.Option(help="cpu or cuda (default: cuda if available).")] = None,
    resume: Annotated[bool, typer.Option("--resume", help="Continue the run in --out where it stopped.")] = False,
    quick: Annotated[
        bool, typer.Option("--quick", help="Scale every budget and evaluation down to a run of a few minutes.")
    ] = False,
) -> None:
    """Train an agent through a curriculum of stages, with evaluation, checkpoints and resume."""
    import torch

    from lanrocli.display import StopRequest, TrainingDisplay
    from lanrocli.train import pick_device
    from lanrocli.train.curriculum import CurriculumError
    from lanrocli.train.pipeline import CurriculumRun, RunError

    if curriculum is None and not quick and not resume:
        raise fail("give a curriculum file (e.g. curricula/reach.yaml), or --quick for the built-in one")
    plan = None if curriculum is None and resume and not quick else _load_plan(curriculum, quick, seed, envs)
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
        else:
            assert plan is not None
            run = CurriculumRun.start(plan, out, torch_device, display)
    except (RunError, CurriculumError) as error:
        raise fail(str(error)) from None
    if run.state.finished:
        try:
            run.complete_tests()  # a run stopped while testing its last stage
        finally:
            run.close()
        Console().print(f"the run in {out} has finished already; see {out / 'report.md'}")
        return
    resume_hint = "lanro train " + (f"{curriculum} " if curriculum else "") + ("--quick " if quick else "") + f"--out {out} --resume"
    with StopRequest() as stop:
        try:
            with display:
                finished = run.run(should_stop=stop.requested)
        finally:
            run.close()
    console = display.console
    if not finished:
        console.print(f"stopped at {run.trainer.progress.env_steps:,} environment steps; checkpoint written.")
        console.print(f"resume with: {resume_hint}")
        raise typer.Exit(130)
    from rich.markdown import Markdown

    report = (out / "report.md").read_text()
    console.print(Markdown(report) if console.is_terminal else report, markup=False)
    console.print(f"run folder: {out}   evaluate: lanro eval {out}   plot: lanro plot {out} --out curves.png")


@app.command("plot")
def plot_command(
    runs: Annotated[list[Path], typer.Argument(help="Run folders (several seeds are drawn as mean and band).")],
    out: Annotated[Path, typer.Option(help="Image to write (.png, .svg or .pdf).")] = Path("curves.png"),
    title: Annotated[str | None, typer.Option(help="Figure title (default: the run names).")] = None,
) -> None:
    """Plot success against environment steps, overall and on correction episodes, with stage boundaries."""
    from lanrocli.train.plot import plot_runs

    try:
        path = plot_runs(runs, out, title)
    except (FileNotFoundError, ValueError) as error:
        raise fail(str(error)) from None
    Console().print(f"wrote {path}")
