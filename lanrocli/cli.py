"""The ``lanro`` command line: parses options, calls the package, prints with rich, sets exit codes."""

from __future__ import annotations

import dataclasses
import inspect
import json
import shlex
import sys
import types
import typing
import warnings
from collections.abc import Callable
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from lanrocli import __version__
from lanrocli.choices import Instruction, Split, Task, check_device
from lanrocli.envs.settings import CORRECTION_LIMIT, EnvSettings
from lanrocli.language import all_sentences, grammar_vocabulary, sample_sentence, sentence_stats
from lanrocli.options import Command, Group

if TYPE_CHECKING:
    from lanrocli.envs.evaluation import EvaluationReport
    from lanrocli.train.curriculum import Curriculum
    from lanrocli.train.testset import Measurement
    from lanrocli.train.trainer import TrainSettings

app = typer.Typer(
    name="lanro",
    help="Train and evaluate a simulated Panda arm that follows language instructions and recovers from corrections.",
    no_args_is_help=True,
    cls=Group,
    pretty_exceptions_enable=False,
)


err_console = Console(stderr=True, soft_wrap=True)


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print ``message`` as an error on stderr and return the exit to raise. The message is escaped, not read
    as rich markup: it quotes files, keys and values, where ``[/x]`` would otherwise raise a MarkupError."""
    err_console.print(f"[bold red]error:[/] {escape(message)}")
    return typer.Exit(code)


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


def _device(value: str | None) -> str | None:
    """Every command's ``--device``, checked by name before anything loads, as ``pick_device`` checks it."""
    if value is not None:
        try:
            check_device(value)
        except ValueError as error:
            raise fail(str(error)) from None
    return value


@app.command("sample-instructions", cls=Command)
def sample_instructions(
    task: Annotated[Task, typer.Option(help="Task whose verbs the instructor uses.")] = Task.REACH,
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


class PolicyName(str, Enum):
    oracle = "oracle"
    mistaken = "mistaken"
    random = "random"


def _percent(rate: float) -> str:
    return "-" if rate != rate else f"{100 * rate:5.1f}%"


def _print_report(report: EvaluationReport, title: str) -> None:
    from lanrocli.envs.figures import FIGURE, JUDGED

    table = Table(title=title)
    for column in ("episodes", "", "success", "95% CI"):
        table.add_column(column, justify="right" if column != "" else "left")
    rows = [
        ("all episodes", report.overall, False),
        ("correction episodes", report.correction_episodes, False),
        ("a correction was spoken (corrected)", report.corrected, False),
    ]
    corrected = report.corrected_by_kind()
    for kind, rate in report.by_kind().items():
        rows += [(f"  {kind}", rate, False), (f"    {kind}, correction spoken", corrected[kind], True)]
    rows += [
        (f"  correction spoken, {FIGURE[f'corrected_success_{form}'].label}", rate, True)
        for form, rate in report.by_form().items()
    ]
    unjudged = False
    for name, rate, split in rows:
        low, high = rate.interval
        ci = "-" if not rate.episodes else f"[{100 * low:.1f}, {100 * high:.1f}]"
        mark = split and rate.episodes > 0 and not rate.judged
        unjudged |= mark
        table.add_row(str(rate.episodes), name + (" *" if mark else ""), _percent(rate.success), ci)
    console = Console()
    console.print(table)
    if unjudged:
        console.print(f"* fewer than {JUDGED} spoken corrections: shown, not judged", highlight=False)
    console.print(f"mean episode length {report.mean_length:.1f} steps, mean return {report.mean_return:.1f}")
    attention = report.attention_on_goal()
    if attention is not None:
        shares = ", ".join(f"{phase} {'-' if v is None else f'{v:.2f}'}" for phase, v in attention.items())
        console.print(f"attention on the goal object (mean share over steps): {shares}", highlight=False)


def _env_summary(env: EnvSettings) -> str:
    parts = [f"{env.objects} objects", env.mode.value]
    if env.correction_rate:
        parts.append(f"corrections {env.correction_rate:g}")
        if env.negations:
            parts.append("negations")
        if env.max_delay:
            parts.append(f"delay <= {env.max_delay}")
        if env.rare_words:
            parts.append("rare words")
        if env.kinds:
            parts.append("kinds " + ",".join(env.kinds))
    if env.random_start:
        parts.append(f"random starts {env.random_start:g}")
    if env.object_start:
        parts.append(f"starts around an object {env.object_start:g}")
    return ", ".join(parts)


def _without_none(hint: Any) -> Any:
    args = [arg for arg in typing.get_args(hint) if arg is not type(None)]
    return args[0] if typing.get_origin(hint) in (typing.Union, types.UnionType) and len(args) == 1 else hint


def _is_list(hint: Any) -> bool:
    """Whether a setting holds several values, which the command line reads comma-separated."""
    return typing.get_origin(_without_none(hint)) is tuple


def _with_env_options(**helps: str) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Give a command one option per ``EnvSettings`` field, from the field's type and ``help`` (or the one
    ``helps`` gives it, where the command reads the setting its own way): typer reads the signature, and the
    command receives them in its ``**env_options``, None where not given."""

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
        ]
        kept = [p for p in signature.parameters.values() if p.kind is not inspect.Parameter.VAR_KEYWORD]
        command.__signature__ = signature.replace(parameters=kept + options)  # type: ignore[attr-defined]
        return command

    return add_options


def _env_changes(options: dict[str, Any]) -> dict[str, Any]:
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


@app.command("eval", cls=Command)
@_with_env_options()
def evaluate_command(
    what: Annotated[
        str,
        typer.Argument(
            metavar="POLICY_OR_CHECKPOINT",
            help="A scripted policy (oracle, mistaken, random), or a trained agent: a checkpoint directory, a "
            "pointer such as RUN/stage-2-corrections/best, or a run folder (its latest checkpoint).",
        ),
    ],
    task: Annotated[Task | None, typer.Option(help="Task (scripted policies; default reach).")] = None,
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
        Instruction,
        typer.Option(
            help="The sentence the agent reads: the instructor's (true), none (blank), or one naming another "
            "object on the table (other; success is the task on that object).",
        ),
    ] = Instruction.TRUE,
    device: Annotated[
        str | None,
        typer.Option(callback=_device, help="cpu, cuda or cuda:N for a trained agent (default: cuda if available)."),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object on stdout.")] = False,
    gif: Annotated[Path | None, typer.Option(help="Write the first episodes as an animated GIF here.")] = None,
    correction_test: Annotated[
        bool,
        typer.Option(
            "--correction-test",
            help="A trained agent on its stage's correction test, as its run measured it: every episode a "
            "correction episode (half the spoken corrections negations, where the stage has them), on episodes "
            "of their own, until enough corrections and negations were spoken to judge each kind and form. "
            "--episodes caps the episodes.",
        ),
    ] = False,
    split: Annotated[
        Split | None,
        typer.Option(
            help="A trained agent on one generalisation split of its run's holdout (docs/generalisation.md), on the "
            "split's own held-out episodes, as its run measured it; --episodes sets how many (default: test.episodes).",
        ),
    ] = None,
    **env_options: Any,
) -> None:
    """Evaluate a scripted policy or a trained agent, overall and per kind and form of correction.

    Success on all episodes, on correction episodes, where a correction was spoken, per kind and form of
    correction, with 95% intervals. For a checkpoint, the environment defaults to the stage it was trained on
    and the episodes to that stage's held-out test episodes; options change them."""
    from lanrocli.envs.env import LanroEnv
    from lanrocli.envs.evaluation import evaluate
    from lanrocli.envs.policies import make_policy

    changes = _env_changes(env_options)
    if correction_test and (seed is not None or instruction is not Instruction.TRUE or gif is not None):
        raise fail("--correction-test runs episodes of its own, as the sentence the instructor speaks; leave out "
                   "--seed, --instruction and --gif")
    if split is not None and (correction_test or seed is not None or instruction is not Instruction.TRUE or gif or changes):
        raise fail("--split runs the split's own episodes and settings; leave out --correction-test, --seed, "
                   "--instruction, --gif and the environment options")
    if what in {p.value for p in PolicyName}:
        if split is not None:
            raise fail("--split measures a trained agent on what its run held out; a scripted policy has no run")
        if correction_test:
            raise fail(
                "--correction-test measures a trained agent on its run's held-out seeds; a scripted policy has none"
            )
        if instruction is not Instruction.TRUE:
            raise fail("--instruction changes what a trained agent reads; scripted policies read no sentence")
        task_name = task or Task.REACH
        first = 0 if seed is None else seed
        try:
            env_settings = EnvSettings(**changes)
            env = LanroEnv(task_name, env_settings, render_mode="rgb_array" if gif else None)
        except ValueError as error:
            raise fail(f"{error} (see 'lanro eval --help')") from None
        try:
            report = evaluate(env, make_policy(what, task_name), episodes or 100, first, gif)
        finally:
            env.close()
        record = {"policy": what, "task": task_name, "env": env_settings.to_dict(), **report.as_dict()}
        where = f"seed {first}"
    elif split is not None:
        agent = _trained_agent(what)
        measurement = _measure_checkpoint(agent, task, device, _split_test(agent, split, episodes))
        report, record, task_name, env_settings = (
            measurement.report, measurement.record, measurement.settings.task, measurement.env
        )
        where = f"the {split.value} split's held-out episodes"
    elif correction_test:
        agent = _trained_agent(what)
        measurement = _measure_checkpoint(agent, task, device, _correction_test(agent, changes, episodes))
        report, record, task_name, env_settings = (
            measurement.report, measurement.record, measurement.settings.task, measurement.env
        )
        quota = record["quota"]
        negations = f" and {quota['negations']} negations" if quota["negations"] else ""
        met = "reached" if record["quota_met"] else f"not reached in {quota['episodes']} episodes"
        where = f"correction test ({quota['spoken']} spoken corrections{negations}: {met})"
    else:
        measurement = _measure_checkpoint(
            _trained_agent(what), task, device, _test(_trained_agent(what), changes, episodes, seed, instruction, gif)
        )
        report, record, task_name, env_settings = (
            measurement.report, measurement.record, measurement.settings.task, measurement.env
        )
        where = "held-out test episodes" if measurement.held_out else f"seed {measurement.first_seed}"
        if instruction is not Instruction.TRUE:
            where += f", instruction {instruction}"
    if record.get("unknown_words"):
        unknown = ", ".join(record["unknown_words"])
        err_console.print(f"[bold yellow]warning:[/] {escape(f'the agent never learned the words {unknown}: it reads each as <unk>')}")
    if as_json:
        typer.echo(json.dumps(record))
        return
    _print_report(report, f"{what} on {task_name}, {_env_summary(env_settings)}, {where}")
    if gif:
        Console().print(f"wrote {gif}")


Check = Callable[["TrainSettings", EnvSettings], None]
Measure = Callable[[Any, Check], "Measurement"]
"""How ``lanro eval`` measures a checkpoint, given the torch device and the check of its settings."""


def _test(
    path: Path, overrides: dict[str, Any], episodes: int | None, seed: int | None, shown: Instruction, gif: Path | None
) -> Measure:
    """The checkpoint at ``path`` on its test episodes, or on others as the options ask."""
    from lanrocli.train.testset import measure

    def run(device: Any, check: Check) -> Measurement:
        return measure(path, episodes or _test_episodes(path), device, overrides, seed, shown, gif, check=check)

    return run


def _correction_test(path: Path, overrides: dict[str, Any], episodes: int | None) -> Measure:
    """The checkpoint at ``path`` on the correction test its run made: the quota sized like its test, at most
    ``episodes`` episodes where given."""
    from lanrocli.train.testset import CORRECTION_QUOTA, correction_test

    def run(device: Any, check: Check) -> Measurement:
        quota = CORRECTION_QUOTA.scaled(_test_episodes(path))
        if episodes is not None:
            quota = dataclasses.replace(quota, episodes=episodes)
        return correction_test(path, quota, device, overrides, check=check)

    return run


def _split_test(path: Path, split: Split, episodes: int | None) -> Measure:
    """The checkpoint at ``path`` on one generalisation split of its run's holdout."""
    from lanrocli.train.testset import split_test

    def run(device: Any, check: Check) -> Measurement:
        return split_test(path, split, episodes or _test_episodes(path), device, check=check)

    return run


def _trained_agent(what: str) -> Path:
    """The checkpoint path ``what`` names, or the shipped agent of that name (``lanro eval push``)."""
    from lanrocli.train.pretrained import agent_path
    from lanrocli.train.runfolder import CheckpointError

    try:
        return agent_path(Path(what))
    except CheckpointError as error:
        raise fail(f"{error}; or name a scripted policy (oracle, mistaken, random)") from None


def _measure_checkpoint(path: Path, task: Task | None, device: str | None, run: Measure) -> Measurement:
    """The trained agent at ``path`` measured as ``run`` does; every problem is a clear error."""
    from lanrocli.train.runfolder import CheckpointError
    from lanrocli.train.trainer import pick_device

    if not path.exists():
        raise fail(f"{path} is neither a scripted policy (oracle, mistaken, random) nor an existing checkpoint path")

    def check(settings: TrainSettings, env_settings: EnvSettings) -> None:
        if task is not None and task != settings.task:
            raise fail(f"{path} was trained on {settings.task}; it cannot be evaluated on {task}")
        if env_settings.objects > settings.slots:
            raise fail(f"{path} observes at most {settings.slots} objects; --objects must not exceed that")

    try:
        return run(pick_device(device), check)
    except (CheckpointError, KeyError) as error:
        raise fail(f"cannot load a trained agent from {path}: {error}") from None
    except ValueError as error:
        raise fail(f"{error} (see 'lanro eval --help')") from None


def _test_episodes(path: Path) -> int:
    """The test-set size of the run that ``path`` belongs to, so ``lanro eval`` repeats what report.md quotes."""
    from lanrocli.train.checkpoint import resolve_checkpoint
    from lanrocli.train.curriculum import Curriculum, CurriculumError, HeldOutConfig, load_curriculum
    from lanrocli.train.runfolder import CONFIG

    config = resolve_checkpoint(path).parent.parent / CONFIG
    try:
        plan: Curriculum = load_curriculum(config)
        return plan.test.episodes
    except CurriculumError:
        return HeldOutConfig().episodes


CURRICULUM_HELP = "A YAML file, or the name of a curriculum that ships with lanro, such as push"


SETTINGS = "KEY=VALUE ..."
"""The metavar of ``--set``: several settings may follow it."""


@app.command("check", cls=Command)
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
        typer.Option("--set", metavar=SETTINGS, help="KEY=VALUE changed in the plan shown, as 'lanro train --set' does."),
    ] = None,
) -> None:
    """Validate a curriculum and print the resolved plan (stages, budgets, total steps) without training."""
    if curriculum is None and not quick:
        if changes:
            raise fail("--set needs the curriculum it applies to")
        _print_packaged()
        return
    plan = _load_plan(curriculum, quick, None, None, changes or [])
    _print_plan(plan)


def _print_packaged() -> None:
    from lanrocli.train.curriculum import load_curriculum, packaged_curricula

    table = Table(title="the curricula that ship with lanro")
    for column in ("name", "task", "stages", "steps at most"):
        table.add_column(column)
    for name, path in packaged_curricula().items():
        plan = load_curriculum(path)
        table.add_row(name, plan.task, ", ".join(stage.name for stage in plan.stages), f"{plan.total_steps:,}")
    console = Console()
    console.print(table)
    console.print("'lanro check NAME' shows one's plan, 'lanro train NAME' runs it", highlight=False)


def _load_plan(
    path: str | None, quick: bool, seed: int | None, envs: int | None, changes: list[str] | None = None
) -> Curriculum:
    """The curriculum to run, with the command line's overrides: the file or packaged curriculum ``path``
    names, scaled down by ``quick`` (to try a file out); without one, with ``quick``, the built-in
    curriculum exactly as written (``curricula/quick.yaml``, whose budgets are small already). Then the
    ``--set`` settings ``changes``, so that they win over the scaling."""
    from lanrocli.train.curriculum import CurriculumError, builtin_curriculum, find_curriculum, load_curriculum
    from lanrocli.train.overrides import SettingError, read_settings

    try:
        settings = read_settings("--set", changes or [])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", FutureWarning)
            plan = load_curriculum(find_curriculum(path)) if path is not None else builtin_curriculum()
        for warning in caught:
            err_console.print(f"[bold yellow]warning:[/] {escape(f'{path}: {warning.message}')}")
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


def _print_plan(plan: Curriculum) -> None:
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
            _env_summary(stage.env.settings()),
            f"{stage.budget.steps:,} steps",
            rule,
            stage.on_budget,
        )
    console.print(table)
    console.print(f"at most {plan.total_steps:,} environment steps in all")
    console.print(
        f"evaluation: {plan.eval.episodes} fresh episodes every {plan.eval.every:,} steps of a stage, and at its end; "
        f"test: {plan.test.episodes} held-out episodes for each stage's last and best agents"
    )
    for name, section in (("agent", plan.agent), ("buffer", plan.buffer)):
        settings = section.settings()
        default = type(settings)()
        changed = {
            f.name: getattr(settings, f.name)
            for f in dataclasses.fields(settings)
            if getattr(default, f.name) != getattr(settings, f.name)
        }
        console.print(f"{name}: default settings ({type(settings).__name__}){', except ' + str(changed) if changed else ''}")
    console.print(f"{plan.updates_per_step:g} update(s) per environment step, from step {plan.learning_starts:,}")


@app.command("train", cls=Command)
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
    envs: Annotated[int | None, typer.Option(min=1, max=64, help="Override the number of parallel environments.")] = None,
    device: Annotated[
        str | None, typer.Option(callback=_device, help="cpu, cuda or cuda:N (default: cuda if available).")
    ] = None,
    resume: Annotated[bool, typer.Option("--resume", help="Continue the run in --out where it stopped.")] = False,
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
        raise fail("give a curriculum (a YAML file, or a packaged one by name: 'lanro check' lists them), or --quick "
                   "for the built-in one")
    if curriculum is None and not quick and changes:
        raise fail("--set needs the curriculum it applies to; a resumed run keeps the settings it started with")
    plan = None if curriculum is None and resume and not quick else _load_plan(curriculum, quick, seed, envs, changes)

    # Only now: a bad curriculum is refused without waiting for torch and pybullet to load.
    import torch

    from lanrocli.display import StopRequest, TrainingDisplay
    from lanrocli.train.checkpoint import CheckpointWriteError
    from lanrocli.train.curriculum import CurriculumError
    from lanrocli.train.pipeline import CurriculumRun, RunError
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
        else:
            assert plan is not None
            run = CurriculumRun.start(plan, out, torch_device, display)
    except (RunError, CurriculumError) as error:
        raise fail(str(error)) from None
    for note in run.notes:
        err_console.print(f"[bold yellow]note:[/] {escape(note)}")
    if run.state.finished:
        try:
            run.complete_tests()  # a run stopped while testing its last stage
        finally:
            run.close()
        Console().print(f"the run in {out} has finished already; see {out / 'report.md'}")
        return
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
        except OSError as error:
            raise fail(
                f"the run stopped: {error}. Its newest checkpoint is whole; fix the cause and resume with: {resume_hint}",
                code=1,
            ) from None
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
    run_folder = shlex.quote(str(out))
    next_commands = {
        f"lanro eval {run_folder}": "the final agent on its held-out test episodes",
        f"lanro plot {run_folder} --out curves.png": "success against environment steps, stage by stage",
        f"lanro play {run_folder}": "give it instructions of your own",
    }
    width = max(map(len, next_commands))
    lines = [f"  {command:<{width}}  # {what}" for command, what in next_commands.items()]
    console.print(f"run folder: {out}\nnext, try:", *lines, sep="\n", markup=False, highlight=False)


@app.command("export", cls=Command)
def export_command(
    source: Annotated[Path, typer.Argument(help="A checkpoint, a pointer such as RUN/stage-3-negations/last, or a run folder.")],
    out: Annotated[Path, typer.Option(help="The folder to write, which must not exist (lanrocli/pretrained/NAME to ship it).")],
    commit: Annotated[str, typer.Option(help="The commit the agent was trained at, recorded with it.")],
) -> None:
    """Write a trained agent's policy alone, with where it came from: an agent to ship.

    The folder holds the commit, seed and test figures the agent came from; lanro eval NAME and lanro play
    NAME find the agents in lanrocli/pretrained."""
    from lanrocli.train.pretrained import export_agent
    from lanrocli.train.runfolder import CheckpointError

    if out.exists():
        raise fail(f"--out {out} exists; give a new folder")
    try:
        written = export_agent(source, out, commit)
    except (CheckpointError, KeyError, ValueError) as error:
        raise fail(f"cannot export {source}: {error}") from None
    size = sum(f.stat().st_size for f in written.iterdir())
    Console().print(f"wrote {written} ({size / 1e6:.2f} MB)")


@app.command("plot", cls=Command)
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
    from lanrocli.sweep.groups import group_runs
    from lanrocli.train.plot import plot_groups

    try:
        groups = [(group.label, group.runs) for group in group_runs(runs)]
        path = plot_groups(groups, out, title or ", ".join(run.name for run in runs))
    except (FileNotFoundError, ValueError) as error:
        raise fail(str(error)) from None
    Console().print(f"wrote {path}")


@app.command("sweep", cls=Command)
def sweep_command(
    curriculum: Annotated[
        str | None,
        typer.Argument(
            metavar="CURRICULUM",
            help=f"{CURRICULUM_HELP}. Optional with --quick (the built-in one) and with --resume.",
        ),
    ] = None,
    out: Annotated[
        Path | None, typer.Option(help="Sweep folder: sweep.yaml and one run folder per trial (default: sweeps/<name>).")
    ] = None,
    seeds: Annotated[
        list[str] | None, typer.Option("--seeds", metavar="SEED ...", help="Seeds, each a trial: --seeds 0 1 2 (default: the curriculum's).")
    ] = None,
    changes: Annotated[
        list[str] | None,
        typer.Option("--set", metavar=SETTINGS, help="KEY=VALUE changed for every trial, by the curriculum's key paths: agent.critics=2."),
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
        float | None,
        typer.Option(min=0.01, help="CPUs per trial (default: one per environment worker, and one for the learner)."),
    ] = None,
    gpus_per_trial: Annotated[
        float, typer.Option(min=0, help="GPUs per trial; above 0 the trials train on cuda.")
    ] = 0.0,
    max_concurrent: Annotated[
        int | None,
        typer.Option(min=1, help="Trials at once (default: as many as the CPUs allow, 1 on two cores)."),
    ] = None,
) -> None:
    """Run a curriculum over seeds, settings and grids of settings on Ray: one ordinary run folder per trial."""
    from lanrocli.sweep import plan as sweeps
    from lanrocli.train.curriculum import CurriculumError
    from lanrocli.train.overrides import SettingError

    spec = None
    if curriculum is not None or quick:
        base = _load_plan(curriculum, quick, None, None)
        try:
            spec = sweeps.SweepSpec.from_options(
                base, str(curriculum or "curricula/quick.yaml"), quick, seeds or [], changes or [], grid or []
            )
        except (sweeps.SweepError, SettingError) as error:
            raise fail(str(error)) from None
    elif not resume:
        raise fail("give a curriculum (a YAML file, or a packaged one by name: 'lanro check' lists them), --quick for "
                   "the built-in one, or --resume")
    elif seeds or changes or grid:
        raise fail("--seeds, --set and --grid need the curriculum file they apply to")
    if out is None:
        if spec is None:
            raise fail("--resume without a curriculum file needs --out: the sweep folder to continue")
        out = Path("sweeps") / spec.plan["name"]
    try:
        trials = spec.resolve() if spec is not None else None  # every trial valid before the folder is touched
        spec = sweeps.open_sweep(out, spec, resume)
        trials = trials or spec.resolve()
    except CurriculumError as error:
        count = len(error.problems)
        raise fail(f"{count} problem{'s' if count > 1 else ''} in the sweep's curricula:\n{error}") from None
    except sweeps.SweepError as error:
        raise fail(str(error)) from None
    try:
        from lanrocli.sweep.execute import Resources, ray_instance, run_sweep
    except ImportError as error:
        raise fail(f"lanro sweep runs on Ray, which is not installed ({error}): pip install -e '.[sweep]'") from None
    from lanrocli.stop import StopRequest
    from lanrocli.sweep.protocol import ENDED_BEFORE, FAILED, FINISHED, PENDING, STOPPED, TrialProgress
    from lanrocli.sweep_display import SweepDisplay

    jobs = sweeps.trial_jobs(out, trials, "cuda" if gpus_per_trial > 0 else "cpu")
    waiting = {job.name for job in jobs}
    rows = [TrialProgress(trial.name, PENDING if trial.name in waiting else ENDED_BEFORE) for trial, _ in trials]
    envs = max(plan.envs for _, plan in trials)
    resources = Resources.choose(envs, cpus_per_trial, gpus_per_trial, max_concurrent, address)
    hint = f"lanro sweep --out {shlex.quote(str(out))} --resume"
    display = SweepDisplay.for_terminal(rows)
    outcome = None
    if jobs:
        display.console.print(f"{len(jobs)} trial(s) of {len(trials)} to run on {resources}", highlight=False)
        try:
            # Ray's start installs a SIGTERM handler of its own: the stop request's comes after it.
            with ray_instance(resources), StopRequest() as stop, display:
                outcome = run_sweep(jobs, resources, out / sweeps.RAY_FOLDER, display, stop.requested, out / sweeps.STOP_FILE)
        except KeyboardInterrupt:
            raise fail(f"aborted: running trials ended without a checkpoint of this moment; resume with: {hint}", 130) from None
        finally:
            (out / sweeps.STOP_FILE).unlink(missing_ok=True)
    statuses = {row.trial: row.status for row in rows} | (outcome.statuses if outcome else {})
    console = display.console
    for name, error in (outcome.errors if outcome else {}).items():
        console.print(f"[bold red]trial {escape(name)} failed:[/] {escape(error)}", highlight=False)
    done = sum(status in (FINISHED, ENDED_BEFORE) for status in statuses.values())
    console.print(f"{done} of {len(statuses)} trials finished; sweep folder: {out}", highlight=False)
    if done < len(statuses):
        stopped = any(status == STOPPED for status in statuses.values())
        console.print(f"{'stopped; ' if stopped else ''}resume with: {hint}", markup=False, highlight=False)
        raise typer.Exit(1 if any(status == FAILED for status in statuses.values()) else 130)
    console.print(f"next: lanro report {shlex.quote(str(out))}   lanro plot {shlex.quote(str(out))} --out curves.png", markup=False, highlight=False)


@app.command("report", cls=Command)
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
    from lanrocli.sweep.report import ReportError, make_report, to_json, to_markdown

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


@app.command("play", cls=Command)
@_with_env_options(
    max_episode_steps=f"Steps per episode (default: {CORRECTION_LIMIT}, as for a correction episode: any episode "
    "may be corrected)."
)
def play_command(
    checkpoint: Annotated[
        Path,
        typer.Argument(
            metavar="CHECKPOINT",
            help="A checkpoint directory, a pointer such as RUN/stage-1-single/best, or a run folder (its latest).",
        ),
    ],
    task: Annotated[
        Task | None, typer.Option(help="Task (default: the checkpoint's; another needs the same actions).")
    ] = None,
    seed: Annotated[int, typer.Option(min=0, help="Episode i draws its scene with seed SEED + i - 1.")] = 0,
    episodes: Annotated[
        int | None, typer.Option(min=1, help="Stop after this many episodes (default: when the input ends).")
    ] = None,
    steps_per_line: Annotated[
        int, typer.Option(min=1, help="Steps the agent acts before each further line is read.")
    ] = 10,
    device: Annotated[
        str | None, typer.Option(callback=_device, help="cpu, cuda or cuda:N (default: cuda if available).")
    ] = None,
    gif: Annotated[
        Path | None, typer.Option(help="Folder for one GIF per episode (episode-1.gif, ...), captioned with the sentence.")
    ] = None,
    gui: Annotated[bool, typer.Option("--gui", help="Show the episodes in PyBullet's window (needs a display).")] = False,
    **env_options: Any,
) -> None:
    """Give a trained agent instructions yourself, and correct it while it acts.

    Each episode draws a scene from the checkpoint's stage (options change it) and shows its objects; the next line
    is the instruction. The agent then acts --steps-per-line steps before each further line: text is a correction,
    appended to the instruction as the instructor does (a later one replaces it), and an empty line lets it go on.
    An episode lasts --max-episode-steps steps and ends sooner when the task holds for the object the sentence
    singles out; the next line is the next episode's instruction. Unknown words are named and read as <unk>;
    a sentence outside the grammar is flagged and read all the same.

    Lines come from standard input, so a script can be piped in, for example:
    printf 'push the red cube\\nsorry the blue cube\\n' | lanro play RUN --gif out.
    When the input ends, the running episode goes on to its end and play stops.
    """
    from lanrocli.play import PlayError, PlayOptions, play

    options = PlayOptions(task, _env_changes(env_options), seed, episodes, steps_per_line, gif, gui, device)
    try:
        play(checkpoint, options, sys.stdin, Console(soft_wrap=True))
    except PlayError as error:
        raise fail(str(error)) from None
