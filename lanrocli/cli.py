"""The ``lanro`` command line: parses options, calls the package, prints with rich, sets exit codes."""

from __future__ import annotations

import json
import sys
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
    from lanrocli.envs.evaluation import EvaluationReport

app = typer.Typer(
    name="lanro",
    help="Train and evaluate a simulated Panda arm that follows language instructions and recovers from corrections.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


err_console = Console(stderr=True)


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
    rows = [("all episodes", report.overall), ("correction episodes", report.corrections)]
    rows += [(f"  {kind}", rate) for kind, rate in report.by_kind().items()]
    rows += [(f"  correction spoken, {name.replace('_', ' ')}", rate) for name, rate in report.by_negation().items()]
    for name, rate in rows:
        low, high = rate.interval
        ci = "-" if not rate.episodes else f"[{100 * low:.1f}, {100 * high:.1f}]"
        table.add_row(str(rate.episodes), name, _percent(rate.success), ci)
    Console().print(table)
    Console().print(f"mean episode length {report.mean_length:.1f} steps, mean return {report.mean_return:.1f}")


@app.command("eval")
def evaluate_command(
    policy: Annotated[PolicyName, typer.Argument(help="Scripted policy to evaluate: oracle, mistaken or random.")],
    task: Annotated[TaskName, typer.Option(help="Task to evaluate on.")] = TaskName.reach,
    objects: Annotated[int, typer.Option(min=2, max=3, help="Objects on the table (2 or 3).")] = 2,
    mode: Annotated[ModeName, typer.Option(help="Which properties vary between objects.")] = ModeName.color,
    correction_rate: Annotated[
        float, typer.Option(min=0.0, max=1.0, help="Share of correction episodes (0 = plain instructions).")
    ] = 0.0,
    negations: Annotated[bool, typer.Option("--negations", help="Allow negating corrections.")] = False,
    max_delay: Annotated[int, typer.Option(min=0, help="Corrections arrive after 0..MAX_DELAY steps.")] = 0,
    rare_words: Annotated[bool, typer.Option("--rare-words", help="Allow rare colour words (common ground).")] = False,
    kinds: Annotated[
        str | None,
        typer.Option(help="Comma-separated kinds: ambiguity,common_ground,instruction_correction,wrong_object."),
    ] = None,
    episodes: Annotated[int, typer.Option(min=1, help="Number of episodes.")] = 100,
    seed: Annotated[int, typer.Option(min=0, help="Episode i uses seed SEED + i.")] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object on stdout.")] = False,
    gif: Annotated[Path | None, typer.Option(help="Write the first episodes as an animated GIF here.")] = None,
) -> None:
    """Evaluate a policy: success overall, on correction episodes, per kind, with 95% intervals."""
    from lanrocli.envs import LanroEnv
    from lanrocli.envs.evaluation import evaluate
    from lanrocli.envs.policies import make_policy

    try:
        env = LanroEnv(
            task=task.value,
            objects=objects,
            mode=mode.value,
            correction_rate=correction_rate,
            negations=negations,
            max_delay=max_delay,
            rare_words=rare_words,
            kinds=None if kinds is None else [k.strip() for k in kinds.split(",") if k.strip()],
            render_mode="rgb_array" if gif else None,
        )
    except ValueError as error:
        raise fail(f"{error} (see 'lanro eval --help')") from None
    try:
        report = evaluate(env, make_policy(policy.value, task.value), episodes, seed, gif)
    finally:
        env.close()
    if as_json:
        typer.echo(json.dumps({"policy": policy.value, "task": task.value, **report.as_dict()}))
        return
    _print_report(report, f"{policy.value} on {task.value}, {objects} objects, {mode.value}, seed {seed}")
    if gif:
        Console().print(f"wrote {gif}")
