"""Curriculum runs: promotion rules, budgets, the run folder, and resuming after SIGINT and SIGKILL."""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from lanrocli.cli.app import app
from lanrocli.config.curriculum import Curriculum, load_curriculum
from lanrocli.core.choices import CorrectionForm, Kind, Split
from lanrocli.core.seeds import correction_test_seed, evaluation_seed, held_out_seed, split_test_seed
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation import blocks
from lanrocli.evaluation.blocks import MeasuringError
from lanrocli.evaluation.evaluate import EvaluationReport
from lanrocli.evaluation.metrics import EpisodeResult, wilson_interval
from lanrocli.evaluation.quota import CORRECTION_QUOTA
from lanrocli.evaluation.splits import CONTROL, CONTROLLED, DROP, SPLIT_FIGURES
from lanrocli.train.checkpoint import AGENT_FILE, resolve_checkpoint
from lanrocli.train.errors import RunError
from lanrocli.train.pipeline import CurriculumRun, RunObserver
from lanrocli.train.recovery import restore_files as _restore_files
from lanrocli.train.report import render_report
from lanrocli.train.runfolder import (
    CONFIG,
    CORRECTION_TEST,
    METRIC_COLUMNS,
    METRICS,
    REPORT,
    SPLITS,
    TEST,
    read_pointer,
    step_checkpoint,
    write_pointer,
)
from lanrocli.train.testset import Measurement, correction_test, split_test
from lanrocli.train.testset import once_per_agent as _once_per_agent
from lanrocli.train.testset import records as _records
from lanrocli.train.trainer import TrainSettings
from tests.train.runs import Baseline, outcome, rows, scalars, tiny, train, wait_for_rows


def report(successes: list[bool], corrected: list[bool] | None = None) -> EvaluationReport:
    corrected = corrected or [False] * len(successes)
    return EvaluationReport(
        [
            EpisodeResult(
                success=s,
                length=5,
                challenge="wrong_object" if c else None,
                form=CorrectionForm.EXCUSE if c else None,
                returned=-4.0,
            )
            for s, c in zip(successes, corrected)
        ]
    )


def scripted(run: CurriculumRun, reports: Iterator[EvaluationReport], seeds: list[int] | None = None) -> None:
    """Replace the run's evaluations by ``reports``, in order, so the test decides what the rule sees;
    ``seeds`` collects the first seed of every evaluation."""

    def evaluate(first_seed: int, episodes: int | None = None) -> EvaluationReport:
        if seeds is not None:
            seeds.append(first_seed)
        return next(reports)

    run.trainer.evaluate = evaluate  # type: ignore[method-assign]


@pytest.mark.slow
def test_promotion_happens_exactly_when_the_pooled_rule_holds(tmp_path: Path) -> None:
    plan = load_curriculum(tiny(tmp_path))
    data = plan.model_dump()
    data["stages"][0]["budget"]["steps"] = 400
    data["stages"][0]["promote"] = {"success": 0.5, "on": "overall", "patience": 2}
    plan = Curriculum.model_validate(data)
    run = CurriculumRun.start(plan, tmp_path / "run")
    # Stage 1, pooled over the last two evaluations: one evaluation is not enough even at 1/2; then 1/4,
    # 1/4 (each evaluation alone at 1/2 would have held), and 3/4 holds.
    stage_one = [report([True, False]), report([False, False]), report([True, False]), report([True, True])]
    rest = [report([False, False], [True, False])] * 4
    scripted(run, iter(stage_one + rest))
    assert run.run()
    run.close()
    first = [r for r in rows(tmp_path / "run") if r["stage_name"] == "first"]
    assert [r["rule_holds"] for r in first] == ["0", "0", "0", "1"]
    assert [float(r["rule_value"]) for r in first] == [0.5, 0.25, 0.25, 0.75]
    assert [int(r["env_steps"]) for r in first] == [40, 80, 120, 160]
    result = run.state.results[0]
    assert (result.ended, result.end, result.evaluations, result.rule_value) == ("promoted", 160, 4, 0.75)
    # The next stage starts where the first ended and is evaluated from its own start.
    second = [int(r["stage_steps"]) for r in rows(tmp_path / "run") if r["stage_name"] == "second"]
    assert second == [40, 80]


def test_a_lower_bound_rule_needs_enough_episodes(tmp_path: Path) -> None:
    data = load_curriculum(tiny(tmp_path)).model_dump()
    data["stages"] = [data["stages"][0]]
    data["stages"][0]["budget"]["steps"] = 200
    data["stages"][0]["promote"] = {"success": 0.5, "patience": 2, "statistic": "lower_bound"}
    run = CurriculumRun.start(Curriculum.model_validate(data), tmp_path / "run")
    # 4 of 4 pooled has a Wilson lower bound of 0.51; 3 of 4 (0.30) does not pass although its mean would.
    scripted(run, iter([report([True, True]), report([True, False]), report([True, True]), report([True, True])]))
    assert run.run()
    run.close()
    assert [r["rule_holds"] for r in rows(tmp_path / "run")] == ["0", "0", "0", "1"]
    assert run.state.results[0].rule_value == pytest.approx(wilson_interval(4, 4)[0])


@pytest.mark.slow
def test_consecutive_evaluations_meet_fresh_episodes(tmp_path: Path) -> None:
    plan = load_curriculum(tiny(tmp_path))
    run = CurriculumRun.start(plan, tmp_path / "run")
    seeds: list[int] = []
    scripted(run, iter([report([False, False], [True, False])] * 6), seeds)
    assert run.run()
    run.close()
    # Two evaluations in each of three stages, each with its own block of episodes, derived from the run's seed.
    expected = [evaluation_seed(plan.seed, stage, k) for stage in range(3) for k in range(2)]
    assert seeds == expected and len(set(seeds)) == 6


def test_a_rule_on_corrected_ignores_episodes_without_a_spoken_correction(tmp_path: Path) -> None:
    data = load_curriculum(tiny(tmp_path)).model_dump()
    data["stages"] = [data["stages"][1]]
    data["stages"][0]["promote"] = {"success": 1.0, "on": "corrected"}
    run = CurriculumRun.start(Curriculum.model_validate(data), tmp_path / "run")
    # All plain episodes succeed but the correction episode fails: no promotion; then the correction succeeds.
    scripted(run, iter([report([True, False], [False, True]), report([False, True], [False, True])]))
    assert run.run()
    run.close()
    assert [r["rule_holds"] for r in rows(tmp_path / "run")] == ["0", "1"]
    assert run.state.results[0].ended == "promoted"


def test_the_evaluation_correction_share_reaches_the_trainer_and_the_report(tmp_path: Path) -> None:
    data = load_curriculum(tiny(tmp_path)).model_dump()
    data["eval"]["correction_rate"] = 1.0
    curriculum = Curriculum.model_validate(data)
    run = CurriculumRun.start(curriculum, tmp_path / "run")
    assert run.trainer.settings.eval_correction_rate == 1.0
    assert "100% of them correction episodes" in render_report(curriculum, run.state, tmp_path / "run")
    run.close()


def test_a_stage_with_its_own_evaluation_is_evaluated_so_from_its_first_step(tmp_path: Path) -> None:
    data = load_curriculum(tiny(tmp_path)).model_dump()
    data["stages"][1]["eval"] = {"every": 20, "episodes": 3, "correction_rate": 1.0}
    data["test"]["episodes"] = 1
    curriculum = Curriculum.model_validate(data)
    run = CurriculumRun.start(curriculum, tmp_path / "run")
    assert run.trainer.settings.eval_episodes == 2 and run.trainer.settings.eval_correction_rate is None
    run.run(should_stop=lambda: run.trainer.progress.env_steps > 80)  # in the second stage, after its entry
    assert (run.trainer.settings.eval_episodes, run.trainer.settings.eval_correction_rate) == (3, 1.0)
    run.run(should_stop=lambda: run.trainer.progress.env_steps > 160)
    assert (run.trainer.settings.eval_episodes, run.trainer.settings.eval_correction_rate) == (2, None)
    run.close()
    evaluations = [(r["stage"], r["stage_steps"], r["episodes"]) for r in rows(tmp_path / "run")]
    assert evaluations == [("1", "40", "2"), ("1", "80", "2")] + [("2", str(s), "3") for s in (20, 40, 60, 80)]
    assert "evaluation on 3 fresh episodes (100% of them" in render_report(curriculum, run.state, tmp_path / "run")


def test_on_budget_stop_ends_the_run_and_the_report_says_so(tmp_path: Path) -> None:
    data = load_curriculum(tiny(tmp_path)).model_dump()
    data["stages"][0]["on_budget"] = "stop"
    run = CurriculumRun.start(Curriculum.model_validate(data), tmp_path / "run")
    scripted(run, iter([report([False, False])] * 2))
    assert run.run()
    run.close()
    assert run.state.finished and run.state.stopped_early
    assert [r.name for r in run.state.results] == ["first"]
    assert "on_budget: stop" in (tmp_path / "run" / REPORT).read_text()


@pytest.mark.slow
def test_the_run_folder_has_every_file(straight: Baseline) -> None:
    out = straight.out
    assert load_curriculum(out / CONFIG) == load_curriculum(straight.curriculum)
    assert [r["stage_name"] for r in rows(out)] == ["first"] * 2 + ["second"] * 2 + ["third"] * 2
    for index, name in enumerate(["first", "second", "third"], start=1):
        folder = out / f"stage-{index}-{name}"
        last, best = read_pointer(folder / "last"), read_pointer(folder / "best")
        assert (last / "buffer.npz").is_file() and (best / "agent.pt").is_file()
        # The stage keeps the resumable checkpoint before its last, to fall back on if the last is damaged.
        start = 80 * (index - 1)
        assert last.name == step_checkpoint(start + 80)
        assert {p.name for p in folder.iterdir() if p.is_dir()} == {last.name, best.name, step_checkpoint(start + 40)}
    assert resolve_checkpoint(out) == read_pointer(out / "stage-3-third" / "last")
    table = (out / REPORT).read_text()
    assert "| 1. first | overall >= 1, 1 pooled | 80 of 80 | budget |" in table and "Status: finished" in table
    # each stage's time shared among its phases, its tests included: five shares that sum to about 100
    lines = [line for line in table.splitlines() if line.startswith(("| 1. first", "| 2. second", "| 3. third"))]
    shares = [[int(x) for x in line.split("|")[-2].strip(" %").split(" / ")] for line in lines[:3]]
    assert "time: collecting / updating / evaluating / tests / rest" in table
    assert all(len(s) == 5 and 98 <= sum(s) <= 102 and s[3] > 0 for s in shares), shares
    # Every stage's agents were measured on its test episodes, and report.md quotes those figures.
    for index, name in enumerate(["first", "second", "third"], start=1):
        tested = json.loads((out / f"stage-{index}-{name}" / "test.json").read_text())
        assert {"last", "best"} <= set(tested) and tested["last"]["episodes"] == 2
        assert tested["last"]["episodes_from"]["first_seed"] == held_out_seed(5, index - 1)
        assert f"| {index}. {name} | last ({read_pointer(out / f'stage-{index}-{name}' / 'last').name})" in table
    assert set(tested["language"]) == {"true", "blank", "other"}
    assert set(tested[CORRECTION_TEST]) == {"last", "best"} and "## Correction test" in table
    # ... and on each generalisation split of the holdout, on held-out episodes of the split's own.
    assert list(tested[SPLITS]) == ["pairs", "correction_words", "late_corrections", "paraphrase"]
    for split, records in tested[SPLITS].items():
        assert set(records) == {"last", "best"}
        for record in records.values():
            assert record["split"] == split and record["episodes"] == 2
            assert record["episodes_from"] == {"split": split, "first_seed": split_test_seed(5, 2, Split(split))}
            # A split that changes the correction alone is also played on its seeds with nothing held out.
            if Split(split) in CONTROLLED:
                control = record[CONTROL]
                assert control["episodes"] == 2 and control["env"] == record["env"]
                assert control["episodes_from"] == {
                    "control_of": split,
                    "first_seed": split_test_seed(5, 2, Split(split)),
                }
                assert set(record[DROP]) == {f.name for f in SPLIT_FIGURES if f.split is Split(split)}
            else:
                assert CONTROL not in record
        assert f"| {split} | last |" in table
    assert "## Generalisation splits" in table
    last = read_pointer(out / "stage-3-third" / "last")
    for split in (Split.PAIRS, Split.LATE_CORRECTIONS):
        assert split_test(last, split, 2).record == tested[SPLITS][split.value]["last"]
    said = CliRunner().invoke(app, ["eval", str(out), "--split", "late_corrections"])
    assert said.exit_code == 0 and "on the control (the same episodes with nothing held out): drop" in said.output


def test_the_last_stage_ends_with_a_correction_test_of_both_agents(tmp_path: Path) -> None:
    data = load_curriculum(tiny(tmp_path)).model_dump()
    data["stages"] = [data["stages"][2]]  # corrections and negations
    run = CurriculumRun.start(Curriculum.model_validate(data), tmp_path / "run")
    scripted(run, iter([report([False, False])] * 2))
    assert run.run()
    run.close()
    tested = json.loads((tmp_path / "run" / "stage-1-third" / TEST).read_text())
    corrections = tested[CORRECTION_TEST]
    assert set(corrections) == {"last", "best"}
    quota = CORRECTION_QUOTA.scaled(2)  # sized like the test's two episodes
    for record in corrections.values():
        assert record["episodes_from"] == {"correction_test": True, "first_seed": correction_test_seed(5, 0)}
        assert record["env"]["correction_rate"] == 1.0 and record["env"]["negation_rate"] == 0.5
        assert record["quota"] == {
            "spoken": quota.spoken,
            "negations": quota.negations,
            "episodes": quota.episodes,
            "second": 0,
        }
        assert record["episodes"] == quota.episodes or record["quota_met"]
    assert correction_test(tmp_path / "run" / "stage-1-third" / "last", quota).record == corrections["last"]
    assert "## Correction test" in (tmp_path / "run" / REPORT).read_text()


def test_resuming_a_run_of_an_older_version_gives_metrics_csv_the_new_columns(tmp_path: Path) -> None:
    out = tmp_path / "run"
    out.mkdir()
    config = tiny(tmp_path).read_text()
    (out / CONFIG).write_text(config)
    old = "stage,stage_name,env_steps,success\n1,first,40,0.5\n"
    notes: list[str] = []
    _restore_files(out, out / "stage-1-first" / step_checkpoint(40), {"files": {CONFIG: config, METRICS: old}}, notes)
    (note,) = notes
    assert "older version" in note and "corrected_success_edit" in note
    assert [r["success"] for r in rows(out)] == ["0.5"] and list(rows(out)[0]) == list(METRIC_COLUMNS)


def test_starting_into_a_used_folder_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(RunError, match="not empty.*--resume"):
        CurriculumRun.start(load_curriculum(tiny(tmp_path)), out)
    assert (out / "notes.txt").read_text() == "mine"


def test_resume_with_a_changed_curriculum_is_refused_with_the_difference(tmp_path: Path) -> None:
    out = tmp_path / "run"
    path = tiny(tmp_path)
    run = CurriculumRun.start(load_curriculum(path), out)
    run.run(should_stop=lambda: run.trainer.progress.env_steps >= 50)
    run.close()
    path.write_text(
        path.read_text().replace("budget: {steps: 80}\n  - name: third", "budget: {steps: 90}\n  - name: third")
    )
    with pytest.raises(RunError, match="differs") as error:
        CurriculumRun.resume(out, load_curriculum(path))
    assert "-    steps: 80" in str(error.value) and "+    steps: 90" in str(error.value)


@pytest.mark.slow
@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGKILL])
def test_interrupted_runs_resume_to_the_same_result(tmp_path: Path, how: signal.Signals, straight: Baseline) -> None:
    path = straight.curriculum
    process = train([str(path), "--out", "cut"], tmp_path)
    wait_for_rows(tmp_path / "cut", 3, process)  # inside the second stage
    os.killpg(process.pid, how)
    output = process.communicate(timeout=120)[0]
    if how is signal.SIGINT:
        assert process.returncode == 130, output
        assert f"lanro train {path} --out cut --resume" in output
    else:
        assert process.returncode == -signal.SIGKILL
    resumed = train([str(path), "--out", "cut", "--resume"], tmp_path)
    assert resumed.wait(timeout=300) == 0, resumed.stdout.read() if resumed.stdout else ""

    assert outcome(tmp_path / "cut") == outcome(straight.out)
    assert [s[0] for s in outcome(tmp_path / "cut")[1]] == ["first", "second", "third"]
    for tag in ("eval/success", "test/last/success"):  # what the stopped process wrote after its checkpoint is purged
        assert scalars(tmp_path / "cut", tag) == scalars(straight.out, tag)


def test_a_best_agent_that_is_the_last_one_is_measured_once(tmp_path: Path) -> None:
    for name in ("step-0000000020", "best-0000000020", "best-0000000010"):
        (tmp_path / name).mkdir()
        (tmp_path / name / AGENT_FILE).write_bytes(b"")
    calls: list[str] = []

    def measured(path: Path) -> Measurement:
        calls.append(path.name)
        record = {"checkpoint": path.name, "success": len(calls)}
        return Measurement(TrainSettings(task="reach"), EnvSettings(), 0, True, report([True]), record)

    write_pointer(tmp_path / "last", "step-0000000020")
    write_pointer(tmp_path / "best", "best-0000000020")
    records = _records(_once_per_agent(tmp_path, ["last", "best"], measured))
    assert calls == ["step-0000000020"] and records["last"]["success"] == records["best"]["success"] == 1
    assert records["best"]["checkpoint"].endswith("best-0000000020")
    write_pointer(tmp_path / "best", "best-0000000010")
    records = _records(_once_per_agent(tmp_path, ["last", "best"], measured))
    assert calls[1:] == ["step-0000000020", "best-0000000010"] and records["best"]["success"] == 3


def test_a_stop_request_during_the_tests_stops_at_once_and_the_resumed_run_tests_alike(tmp_path: Path) -> None:
    data = load_curriculum(tiny(tmp_path)).model_dump()
    data["stages"] = [data["stages"][2]]  # the last stage's tests: language check, correction test, splits
    plan = Curriculum.model_validate(data)
    measured: list[int] = []

    class StopOnceTested(RunObserver):
        def on_evaluation(self, run: CurriculumRun, row: dict) -> None:  # the tests follow the last evaluation
            measured.append(len(row))

    requested = {"episodes": 0}

    def should_stop() -> bool:  # asked after every test episode once training is over: the third says stop
        if measured and len(measured) == 2:
            requested["episodes"] += 1
        return requested["episodes"] >= 3

    run = CurriculumRun.start(plan, tmp_path / "run", observer=StopOnceTested())
    scripted(run, iter([report([False, False])] * 2))
    assert not run.run(should_stop)
    run.close()
    folder = tmp_path / "run" / "stage-1-third"
    assert requested["episodes"] == 3 and not (folder / TEST).is_file()  # stopped at the third test episode

    resumed = CurriculumRun.resume(tmp_path / "run", plan)
    assert resumed.state.finished and resumed.run()
    resumed.close()
    straight = CurriculumRun.start(plan, tmp_path / "straight")
    scripted(straight, iter([report([False, False])] * 2))
    assert straight.run()
    straight.close()
    again, once = (
        json.loads((root / "stage-1-third" / TEST).read_text()) for root in (tmp_path / "run", tmp_path / "straight")
    )
    assert again == once


@pytest.mark.slow
def test_a_run_with_a_question_test_stopped_and_resumed_ends_as_an_uninterrupted_one(tmp_path: Path) -> None:
    """The question test at the end of the run, stopped once during training and once during the tests:
    the resumed run's test.json, metrics and stages are the uninterrupted run's."""
    text = tiny(tmp_path).read_text()
    text = text.replace("agent: {batch_size: 16}", "agent: {batch_size: 16, architecture: objects}")
    text = text.replace(
        "negations: true, max_episode_steps: 20}", "negations: true, max_episode_steps: 20, max_corrections: 2}"
    )
    path = tmp_path / "ask.yaml"
    path.write_text(text + "questions: {level: 0.8, calibration_episodes: 10, episodes: 6}\n")
    plan = load_curriculum(path)
    straight = CurriculumRun.start(plan, tmp_path / "straight")
    straight.run()
    straight.close()
    cut = CurriculumRun.start(plan, tmp_path / "cut")
    cut.run(should_stop=lambda: cut.trainer.progress.env_steps >= 50)
    cut.close()
    resumed = CurriculumRun.resume(tmp_path / "cut", plan)
    assert not resumed.run(should_stop=lambda: resumed.state.finished)  # stops in the last stage's tests
    resumed.close()
    assert not (tmp_path / "cut" / "stage-3-third" / TEST).exists()
    again = CurriculumRun.resume(tmp_path / "cut", plan)
    again.run()
    again.close()
    assert outcome(tmp_path / "cut") == outcome(tmp_path / "straight")
    asked = json.loads((tmp_path / "straight" / "stage-3-third" / TEST).read_text())["question_test"]["last"]
    assert asked["env"]["questions"] == 1 and set(asked["questions"]) <= {"clear", *(k.value for k in Kind)}
    assert asked["episodes"] == 6 == asked["off"]["episodes"] and asked["calibration"]["episodes"] == 10
    report = (tmp_path / "straight" / REPORT).read_text()
    assert "## Question test" in report and f"| last | {next(iter(asked['questions'])).replace('_', ' ')} |" in report


def test_a_worker_killed_in_the_tests_is_reported_and_the_resumed_run_tests_as_one_process(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The last stage's tests over two worker processes, one of them killed: the run stops with a
    MeasuringError and no test.json; resumed, its tests equal those of the same run resumed to measure in one
    process."""
    monkeypatch.setattr(blocks, "CHUNK", 4)  # ten test episodes make blocks for both workers
    data = load_curriculum(tiny(tmp_path)).model_dump()
    data["stages"] = [data["stages"][2]]
    data["test"] = {"episodes": 10}
    plan = Curriculum.model_validate(data)
    killed: list[int] = []

    def kill_a_worker() -> bool:
        if run.state.finished and not killed:
            for worker in multiprocessing.active_children():
                killed.append(worker.pid or 0)
                os.kill(worker.pid or 0, signal.SIGKILL)
        return False

    run = CurriculumRun.start(plan, tmp_path / "run")
    run.workers = 2
    with pytest.raises(MeasuringError, match="killed, or ran out of memory"):
        run.run(kill_a_worker)
    run.close()
    assert killed and not (tmp_path / "run" / "stage-1-third" / TEST).exists()
    shutil.copytree(tmp_path / "run", tmp_path / "here")
    resumed = CurriculumRun.resume(tmp_path / "run", plan)
    resumed.workers = 2
    assert resumed.run()
    resumed.close()
    here = CurriculumRun.resume(tmp_path / "here", plan)
    assert here.workers == 1 and here.run()
    here.close()
    assert (tmp_path / "run" / "stage-1-third" / TEST).is_file()
    assert outcome(tmp_path / "run") == outcome(tmp_path / "here")
