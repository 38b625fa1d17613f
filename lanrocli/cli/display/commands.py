"""What the commands print besides a training's or a sweep's live display (:mod:`lanrocli.cli.display.training`,
:mod:`lanrocli.sweep.display`): the grammar's sentences and statistics, an evaluation's report, a
curriculum's plan, the packaged curricula, and a finished run's report. Light, like the command line."""

from __future__ import annotations

import dataclasses
import json
import shlex
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from rich.console import Console
from rich.table import Table

from lanrocli.envs.settings import EnvSettings
from lanrocli.language import Sentence, Vocabulary
from lanrocli.language.grammar import SentenceStats

if TYPE_CHECKING:
    from lanrocli.config.curriculum import Curriculum
    from lanrocli.evaluation.evaluate import EvaluationReport


def print_grammar_stats(task: str, stats: SentenceStats, vocab: Vocabulary) -> None:
    table = Table(title=f"grammar statistics: {task}", show_header=False)
    table.add_row("sentences", str(stats.sentences))
    table.add_row("distinct sentences", str(stats.distinct))
    table.add_row("vocabulary size (with <pad>, <unk>)", str(len(vocab)))
    table.add_row("L (padded length)", str(vocab.max_length))
    for form, count in stats.by_form.items():
        table.add_row(f"instruction form {form}", str(count))
    for kind, count in stats.by_beginning.items():
        table.add_row(f"correction beginning {kind}", str(count))
    Console().print(table)


def write_sentences_json(sentences: Iterable[Sentence], vocab: Vocabulary, out: TextIO) -> None:
    """A JSON array written one sentence at a time, so that ``--all`` streams the whole grammar without
    holding it."""
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


def print_sampled(sentences: Iterable[Sentence], vocab: Vocabulary, title: str) -> None:
    table = Table(title=title)
    table.add_column("#", justify="right")
    table.add_column("instruction")
    table.add_column("correction")
    table.add_column("tokens")
    for i, s in enumerate(sentences):
        table.add_row(str(i), s.instruction, s.correction or "", " ".join(map(str, vocab.encode(s.text))))
    Console().print(table)


def _percent(rate: float) -> str:
    return "-" if rate != rate else f"{100 * rate:5.1f}%"


def print_evaluation(report: EvaluationReport, title: str) -> None:
    from lanrocli.evaluation.metrics import FIGURE, JUDGED

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
    first = _percent(report.named_first.success).strip()
    console.print(f"the named object was the first the task held for in {first} of the episodes", highlight=False)
    attention = report.attention_on_goal()
    if attention is not None:
        shares = ", ".join(f"{phase} {'-' if v is None else f'{v:.2f}'}" for phase, v in attention.items())
        console.print(f"attention on the goal object (mean share over steps): {shares}", highlight=False)


def _share(rate: dict[str, Any]) -> str:
    """A rate as a percentage and its 95% interval, short enough for a narrow terminal."""
    if not rate["episodes"]:
        return "-"
    low, high = rate["ci"]
    return f"{100 * rate['success']:.1f} ({100 * low:.0f}-{100 * high:.0f})"


def _count(figure: dict[str, Any]) -> str:
    low, high = figure["ci"]
    return f"{figure['per_episode']:.2f} ({low:.2f}-{high:.2f})"


def print_questions(record: dict[str, Any], title: str) -> None:
    """A question test's figures per kind of episode, with questions and without (``question_test``), each
    with its 95% interval; ``--json`` has the counts too."""
    table = Table(title=title)
    columns = ("kind", "episodes", "asked, %", "questions / ep.", "success, %", "off", "wrong obj. / ep.", "off")
    for column in columns:
        table.add_column(column, justify="left" if column == "kind" else "right")
    off = record["questions_off"]
    for kind, figures in record["questions"].items():
        table.add_row(
            kind.replace("_", " "),
            str(figures["episodes"]),
            _share(figures["asked"]),
            f"{figures['questions']['per_episode']:.2f}",
            _share(figures["success"]),
            _share(off[kind]["success"]),
            _count(figures["wrong_objects"]),
            _count(off[kind]["wrong_objects"]),
        )
    console = Console()
    console.print(table)
    calibration, coverage = record["calibration"], record["coverage"]
    console.print(
        f"off: the same episodes with questions off. The rule asks unless its attention keeps exactly one object at "
        f"weight >= {calibration['threshold']:.4f}, fitted on {calibration['episodes']} calibration scenes to keep "
        f"the meant object in {100 * calibration['level']:.0f}% of them; kept on the test's scenes: "
        f"{_share(coverage)}; success without a question: {_share(record['acted_without_asking'])} of "
        f"{record['acted_without_asking']['episodes']}",
        highlight=False,
    )


def env_summary(env: EnvSettings) -> str:
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
    if env.mistake_start:
        parts.append(f"starts after a mistake {env.mistake_start:g}")
    return ", ".join(parts)


def print_packaged() -> None:
    from lanrocli.config.curriculum import load_curriculum, packaged_curricula

    table = Table(title="the curricula that ship with lanro")
    for column in ("name", "task", "stages", "steps at most"):
        table.add_column(column)
    for name, path in packaged_curricula().items():
        plan = load_curriculum(path)
        table.add_row(name, plan.task, ", ".join(stage.name for stage in plan.stages), f"{plan.total_steps:,}")
    console = Console()
    console.print(table)
    console.print("'lanro check NAME' shows one's plan, 'lanro train NAME' runs it", highlight=False)


def print_plan(plan: Curriculum) -> None:
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
            env_summary(stage.env.settings()),
            f"{stage.budget.steps:,} steps",
            rule,
            stage.on_budget,
        )
    console.print(table)
    console.print(f"at most {plan.total_steps:,} environment steps in all")
    console.print(
        f"evaluation: {plan.eval.described()} every {plan.eval.every:,} steps of a stage, and at its end; "
        f"test: {plan.test.episodes} held-out episodes for each stage's last and best agents"
    )
    for i, stage in enumerate(plan.stages):
        if (own := plan.evaluation(i)) != plan.eval:
            console.print(f"  stage {i + 1} ({stage.name}) instead: {own.described()} every {own.every:,} steps")
    if (questions := plan.questions) is not None:
        console.print(
            f"question test: the final agents ask by a rule calibrated on {questions.calibration_episodes} scenes to "
            f"level {questions.level:g}, on {questions.episodes} held-out episodes, and with questions off; a question "
            f"takes {questions.steps} step(s) and {questions.penalty:g} reward (docs/questions.md)"
        )
    for name, section in (("agent", plan.agent), ("buffer", plan.buffer)):
        settings = section.settings()
        default = type(settings)()
        changed = {
            f.name: getattr(settings, f.name)
            for f in dataclasses.fields(settings)
            if getattr(default, f.name) != getattr(settings, f.name)
        }
        console.print(
            f"{name}: default settings ({type(settings).__name__}){', except ' + str(changed) if changed else ''}"
        )
    for i, stage in enumerate(plan.stages):
        if own_keys := {key: value for key, value in stage.buffer.model_dump().items() if value is not None}:
            console.print(f"  stage {i + 1} ({stage.name}) samples with {own_keys}")
    console.print(f"{plan.updates_per_step:g} update(s) per environment step, from step {plan.learning_starts:,}")


def print_finished_run(console: Console, out: Path) -> None:
    """The run's ``report.md``, rendered in a terminal, and the commands that look further."""
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
