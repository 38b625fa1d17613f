"""``report.md``: how each stage of a run went, and its agents on held-out test episodes, in Markdown; and
whether a run has ended, as its report says."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from lanrocli.config.curriculum import Curriculum
from lanrocli.core.choices import Kind
from lanrocli.evaluation.metrics import ATTENTION, FIGURES, JUDGED, PHASES
from lanrocli.evaluation.splits import split_lines, with_interval
from lanrocli.train.clock import RATES
from lanrocli.train.runfolder import (
    BEST,
    CORRECTION_TEST,
    LANGUAGE,
    LAST,
    QUESTION_TEST,
    REPORT,
    SPLITS,
    TEST,
    stage_folder,
)
from lanrocli.train.runstate import RunState

STATUS = "Status: "
"""How the line of ``report.md`` that says whether the run has ended begins."""
FINISHED = "finished"
STOPPED_BY_BUDGET = "stopped: a budget ran out with on_budget: stop"


def write_report(out: Path, curriculum: Curriculum, state: RunState) -> None:
    (out / REPORT).write_text(render_report(curriculum, state, out))


def render_report(curriculum: Curriculum, state: RunState, out: Path) -> str:
    """``report.md``: how each stage went, and its agents on held-out test episodes, in Markdown."""
    lines = [
        f"# {curriculum.name}: {curriculum.task}",
        "",
        f"Seed {curriculum.seed}, {curriculum.envs} environments; evaluation on {curriculum.eval.described()} "
        f"every {curriculum.eval.every:,} steps; each stage's agents tested on "
        f"{curriculum.test.episodes} held-out episodes.",
        "",
        *_stage_lines(curriculum, state),
    ]
    tests = {}
    for result in state.results:
        path = out / stage_folder(result.index, curriculum.stages[result.index].name) / TEST
        if path.is_file():
            tests[result.index] = (result.name, json.loads(path.read_text()))
    if tests:
        lines += _test_lines(tests)
    return "\n".join(lines) + "\n"


def _stage_lines(curriculum: Curriculum, state: RunState) -> list[str]:
    lines = [
        "## Stages",
        "",
        "| stage | rule | steps | ended | evaluations | rule's value at the end | wall time | steps/s collecting "
        "| updates/s | steps/s evaluating | tests | time: collecting / updating / evaluating / tests / rest |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for result in state.results:
        stage = curriculum.stages[result.index]
        rule = stage.promote.described() if stage.promote else "-"
        own = curriculum.evaluation(result.index)
        if own != curriculum.eval:
            judged = f"evaluation on {own.described()} every {own.every:,} steps"
            rule = judged if rule == "-" else f"{rule}; {judged}"
        lines.append(
            f"| {result.index + 1}. {result.name} | {rule} | {result.end - result.start:,} of "
            f"{stage.budget.steps:,} | {result.ended} | {result.evaluations} | {_percent(result.rule_value)} | "
            f"{result.wall_time / 60:.1f} min | {_speeds(state.rates(result), result.test_seconds)} | "
            f"{_shares(state.shares(result))} |"
        )
    total = state.results[-1].end if state.results else 0
    status = FINISHED if state.finished else "running"
    if state.stopped_early:
        status = STOPPED_BY_BUDGET
    return lines + ["", f"{STATUS}{status}. {total:,} environment steps in all. (Wall time is cumulative.)"]


def _speeds(rates: dict[str, float | None] | None, test_seconds: float | None) -> str:
    """The stage's rate in each phase and its tests' minutes, as table cells ("-" where not known)."""
    cells = [f"{rates[phase]:,.0f}" if rates and rates.get(phase) is not None else "-" for phase in RATES]
    return " | ".join([*cells, "-" if test_seconds is None else f"{test_seconds / 60:.1f} min"])


def _shares(shares: dict[str, float] | None) -> str:
    """A stage's time by phase as ``41 / 39 / 4 / 14 / 2 %``, or "-" where it is not known."""
    return "-" if shares is None else " / ".join(f"{100 * share:.0f}" for share in shares.values()) + " %"


def run_ended(out: Path) -> bool:
    """Whether the run in ``out`` has ended, as its ``report.md`` says once the last stage's tests are written: a
    run killed after its last checkpoint but before those tests has not, and resuming it completes them."""
    path = out / REPORT
    if not path.is_file():
        return False
    ended = tuple(f"{STATUS}{status}." for status in (FINISHED, STOPPED_BY_BUDGET))
    return any(line.startswith(ended) for line in path.read_text().splitlines())


def _test_lines(tests: dict[int, tuple[str, dict[str, Any]]]) -> list[str]:
    """The tables of the stages' ``test.json`` records, ``tests`` keyed by stage index."""
    lines = [
        "",
        "## Test: held-out episodes",
        "",
        "Success with 95% Wilson interval (episodes). Nothing in the run was selected on these episodes. "
        "Per kind and after a negation: success on the episodes in which that correction was spoken.",
        "",
        "| stage | agent | success | correction episodes | corrected | ambiguity | common ground | "
        "instruction correction | wrong object | after a negation |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for index, (name, record) in tests.items():
        lines += _test_rows(index, name, record)
    language = next((record[LANGUAGE] for _, record in reversed(tests.values()) if LANGUAGE in record), None)
    if language:
        lines += [
            "",
            "## Language check: the final agent on plain test episodes",
            "",
            "`true`: the instructor's sentence; `blank`: no words; `other`: a sentence naming another object, "
            "won when the task holds for that object. *Named object first*: the share of episodes in which "
            "the first object the task held for was the one the sentence names (the goal for `blank`). The "
            "check is judged on it: an agent that reads its instruction puts the named object first about as "
            "often with `other` as with `true`, and with `blank` at or below chance, one in as many objects. "
            "Success with `blank` can exceed chance where an arm moves on from a wrong object to the next, "
            "which a plain episode does not punish; the object it goes to first cannot.",
            "",
            "| instruction | success | named object first |",
            "|---|---|---|",
        ]
        for shown, r in language.items():
            overall = {"episodes": r["episodes"], "success": r["success"], "ci": r["success_ci"]}
            first = with_interval(r["named_first"]) if "named_first" in r else "-"
            lines.append(f"| {shown} | {with_interval(overall)} | {first} |")
    corrections = next(
        (record[CORRECTION_TEST] for _, record in reversed(tests.values()) if CORRECTION_TEST in record), None
    )
    if corrections:
        lines += correction_test_lines(corrections)
    final = next((record for _, record in reversed(tests.values()) if SPLITS in record), None)
    if final:
        lines += split_lines(final[SPLITS], {agent: final[agent] for agent in (LAST, BEST) if agent in final})
    asked = next((record[QUESTION_TEST] for _, record in reversed(tests.values()) if QUESTION_TEST in record), None)
    if asked:
        lines += question_test_lines(asked)
    return lines


def question_test_lines(records: dict[str, dict[str, Any]]) -> list[str]:
    """The section of ``report.md`` on the question test of the final stage's agents (``records`` by agent)."""
    lines = [
        "",
        '## Question test: asking "which one?"',
        "",
        "The final agents ask by a rule calibrated on their attention (docs/questions.md), and the same agents "
        "play the same held-out episodes with questions off. Every episode a correction episode, the kinds "
        "alike; *clear*: plain and wrong-object episodes, whose instruction singles out the goal. Rates with 95% "
        "Wilson interval (episodes); wrong-object actions per episode with a 95% interval (total).",
        "",
        "| agent | kind | asked | success | success, questions off | wrong-object actions | questions off |",
        "|---|---|---|---|---|---|---|",
    ]
    for agent, r in records.items():
        for kind, figures in r["questions"].items():
            off = r["questions_off"][kind]
            lines.append(
                f"| {agent} | {kind.replace('_', ' ')} | {with_interval(figures['asked'])} | "
                f"{with_interval(figures['success'])} | {with_interval(off['success'])} | "
                f"{_per_episode(figures['wrong_objects'])} | {_per_episode(off['wrong_objects'])} |"
            )
    lines.append("")
    for agent, r in records.items():
        calibration, unasked = r["calibration"], r["acted_without_asking"]
        lines.append(
            f"- {agent}: threshold {calibration['threshold']:.4g}, fitted on {calibration['episodes']} scenes to keep "
            f"the meant object in {100 * calibration['level']:.0f}% of them; kept on the test's scenes: "
            f"{with_interval(r['coverage'])}; success without a question: {with_interval(unasked)}."
        )
    return lines


def _per_episode(figure: dict[str, Any]) -> str:
    low, high = figure["ci"]
    return f"{figure['per_episode']:.2f} [{low:.2f}, {high:.2f}] ({figure['total']})"


def correction_test_lines(records: dict[str, dict[str, Any]]) -> list[str]:
    """The section of ``report.md`` on the correction test of the final stage's agents (``records`` by agent)."""
    split = [figure for figure in FIGURES if figure.split]
    quota = next(iter(records.values()))["quota"]
    negations = f" and {quota['negations']} negations" if quota["negations"] else ""
    lines = [
        "",
        "## Correction test: the final stage's agents on correction episodes",
        "",
        "Every episode a correction episode (half the spoken corrections negations, where the stage has them), "
        f"run until {quota['spoken']} corrections{negations} were spoken, or for {quota['episodes']} episodes; "
        "episodes of their own, apart from the test's. Success where a correction was spoken, with 95% Wilson "
        f"interval (spoken); per kind and form: success (spoken), `*` where fewer than {JUDGED} were spoken: "
        "shown, not judged.",
        "",
        "| agent | episodes | corrected | " + " | ".join(figure.label for figure in split) + " |",
        "|---|---|---|" + "---|" * len(split),
    ]
    for agent, r in records.items():
        cells = [_judged(*figure.read(r)) for figure in split]
        met = "" if r["quota_met"] else ", quota not met"
        lines.append(
            f"| {agent} ({r['checkpoint'].split('/')[-1]}) | {r['episodes']}{met} | {with_interval(r['corrected'])} | "
            + " | ".join(cells)
            + " |"
        )
    attention = {agent: r[ATTENTION] for agent, r in records.items() if r.get(ATTENTION)}
    if attention:
        lines += [
            "",
            "Share of the actor's attention on the goal object, mean over steps: before any correction (plain), "
            "and after a correction of each form.",
            "",
            "| agent | " + " | ".join(PHASES) + " |",
            "|---|" + "---|" * len(PHASES),
        ]
        for agent, shares in attention.items():
            lines.append(f"| {agent} | " + " | ".join(_share(shares.get(phase)) for phase in PHASES) + " |")
    return lines


def _judged(episodes: int, success: float | None) -> str:
    """A kind's or form's success as ``75% (40)``, marked ``*`` on too few spoken corrections to judge it."""
    if not episodes or success is None:
        return "-"
    return f"{100 * success:.0f}% ({episodes}){'*' if episodes < JUDGED else ''}"


def _share(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _test_rows(index: int, name: str, record: dict[str, Any]) -> list[str]:
    rows = []
    for agent in (LAST, BEST):
        if agent not in record:
            continue
        r = record[agent]
        overall = {"episodes": r["episodes"], "success": r["success"], "ci": r["success_ci"]}
        episodes = {
            "episodes": r["correction_episodes"],
            "success": r["correction_episode_success"],
            "ci": r["correction_episode_success_ci"],
        }
        kinds = [_with_count(r["by_kind"].get(kind.value, {}).get("corrected")) for kind in Kind]
        rows.append(
            f"| {index + 1}. {name} | {agent} ({r['checkpoint'].split('/')[-1]}) | {with_interval(overall)} | "
            f"{with_interval(episodes)} | {with_interval(r['corrected'])} | {' | '.join(kinds)} | "
            f"{_with_count(r['by_negation']['with_negation'])} |"
        )
    return rows


def _percent(value: float | None) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{100 * value:.0f}%"


def _with_count(rate: dict[str, Any] | None) -> str:
    return "-" if not rate or not rate["episodes"] else f"{100 * rate['success']:.0f}% ({rate['episodes']})"
