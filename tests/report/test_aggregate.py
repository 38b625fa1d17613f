"""lanro report on run folders made by hand: figures per stage, groups by setting, their comparison, the JSON
and Markdown forms, and no torch, pybullet or Ray loaded to make them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from lanrocli.cli.app import app
from lanrocli.config.curriculum import load_curriculum
from lanrocli.report.aggregate import ReportError, make_report
from lanrocli.report.groups import group_runs
from lanrocli.report.output import to_json, to_markdown
from lanrocli.sweep.plan import SWEEP_FILE, SweepSpec
from lanrocli.train.runfolder import CONFIG, LATEST, REPORT, TEST
from tests.train.runs import tiny

runner = CliRunner()


def rate(episodes: int, success: float | None) -> dict:
    return {"episodes": episodes, "success": success, "ci": [0.0, 1.0]}


def record(success: float, corrected: float | None) -> dict:
    return {
        "episodes": 100,
        "success": success,
        "success_ci": [0.0, 1.0],
        "correction_episodes": 50,
        "correction_episode_success": success,
        "corrected": rate(20 if corrected is not None else 0, corrected),
        "by_kind": {"ambiguity": {**rate(10, 0.5), "corrected": rate(5 if corrected is not None else 0, corrected)}},
        "by_negation": {"with_negation": rate(0, None), "without_negation": rate(0, None)},
    }


def make_run(folder: Path, seed: int, stages: list[tuple[int, bool, float, float | None]], critics: int = 1) -> Path:
    """A run folder as 'lanro train' leaves it, with the stages ``(steps, promoted, success, corrected)``."""
    plan = load_curriculum(tiny(folder.parent)).model_dump(mode="json")
    plan["seed"], plan["agent"]["critics"] = seed, critics
    folder.mkdir(parents=True)
    (folder / CONFIG).write_text(yaml.safe_dump(plan))
    results, start = [], 0
    for index, (steps, promoted, success, corrected) in enumerate(stages):
        name = plan["stages"][index]["name"]
        stage = folder / f"stage-{index + 1}-{name}"
        (stage / "step-1").mkdir(parents=True)
        (stage / TEST).write_text(json.dumps({"last": record(success, corrected), "best": record(1.0, 1.0)}))
        results.append(
            {
                "index": index,
                "name": name,
                "start": start,
                "end": start + steps,
                "ended": "promoted" if promoted else "budget",
            }
        )
        start += steps
    (stage / "step-1" / "state.json").write_text(json.dumps({"extra": {"run": {"results": results}}}))
    (folder / LATEST).write_text(f"{stage.name}/step-1\n")
    (folder / REPORT).write_text("Status: finished. 1 environment steps in all.\n")
    return folder


@pytest.fixture
def runs(tmp_path: Path) -> list[Path]:
    return [
        make_run(tmp_path / "a0", 0, [(40, True, 0.8, None), (80, False, 0.6, 0.5)]),
        make_run(tmp_path / "a1", 1, [(80, True, 0.6, None), (80, False, 0.4, None)]),
        make_run(tmp_path / "b0", 0, [(40, True, 1.0, None)], critics=2),
    ]


def test_figures_per_stage_over_runs(runs: list[Path]) -> None:
    report = make_report(runs[:2])
    (group,) = report.groups
    first, second = group.cells[("reach", 0, "first")], group.cells[("reach", 1, "second")]
    assert first["stage_steps"].mean.value == 60 and group.promoted[("reach", 0, "first")] == 2
    assert first["success"].mean.value == pytest.approx(0.7) and first["success"].mean.ci == pytest.approx((0.6, 0.8))
    assert "corrected_success" not in first  # no run had a spoken correction there
    assert second["corrected_success"].values == [0.5] and second["corrected_success"].mean.runs == 1
    assert second["corrected_success_ambiguity"].values == [0.5]
    assert first["success"].iqm is None  # fewer than five runs
    data = to_json(report)["groups"][0]
    metrics = data["stages"][0]["metrics"]
    assert set(metrics["success"]) >= {"mean", "ci", "runs"} and metrics["success"]["runs"] == 2
    assert metrics["stage_steps"]["promoted"] == 2 and data["ended"] == 2
    assert to_json(make_report(runs[:2], "best"))["groups"][0]["stages"][0]["metrics"]["success"]["mean"] == 1.0


def add_correction_test(run: Path, negation: float, negations: int) -> None:
    """The last stage's correction test, as the run's final test writes it, with ``negations`` spoken negations."""
    test = next(run.glob("stage-*")) / TEST
    tested = json.loads(test.read_text())
    spoken = {
        **record(0.9, 0.6),
        "by_form": {"excuse": rate(300, 0.7), "negation": rate(negations, negation), "edit": rate(0, None)},
    }
    tested["correction_test"] = {"last": spoken, "best": spoken}
    test.write_text(json.dumps(tested))


def test_the_correction_test_is_aggregated_per_form_and_marks_what_is_not_judged(tmp_path: Path) -> None:
    runs = [make_run(tmp_path / f"r{seed}", seed, [(40, True, 0.5, 0.5)]) for seed in (0, 1)]
    add_correction_test(runs[0], 0.4, 150)
    add_correction_test(runs[1], 0.6, 20)
    report = make_report(runs)
    cells = report.groups[0].cells[("reach", 0, "first")]
    negation = cells["correction_test_corrected_success_negation"]
    assert negation.values == [0.4, 0.6] and negation.mean.value == pytest.approx(0.5)
    assert negation.fewest == 20 and not negation.judged  # one run heard only 20
    assert cells["correction_test_corrected_success_excuse"].judged
    assert "correction_test_corrected_success_edit" not in cells  # no run heard an edit
    assert cells["corrected_success_ambiguity"].fewest == 5 and not cells["corrected_success_ambiguity"].judged
    assert cells["success"].judged  # not a kind or a form: never marked
    metrics = to_json(report)["groups"][0]["stages"][0]["metrics"]
    assert metrics["correction_test_corrected_success_negation"]["judged"] is False
    text = to_markdown(report)
    assert "| correction test: after a negation | 50.0 [40.0, 60.0]* |" in text
    assert "| correction test: after an excuse | 70.0 [70.0, 70.0] |" in text
    assert "\\* Some run heard fewer than 30" in text


def test_settings_are_grouped_and_compared(runs: list[Path]) -> None:
    groups = group_runs(runs)
    assert [g.label for g in groups] == ["agent.critics=1", "agent.critics=2"]
    assert [len(g.runs) for g in groups] == [2, 1]
    report = make_report(runs)
    beats = report.comparisons[(("reach", 0, "first"), "success", 1)]
    assert beats.value == 1.0  # 1.0 beats both 0.8 and 0.6
    steps = report.comparisons[(("reach", 0, "first"), "stage_steps", 1)]
    assert steps.value == 0.75  # 40 steps: fewer than 80, tied with 40
    text = to_markdown(report)
    assert "| figure | agent.critics=1 (2 runs) | agent.critics=2 (1 runs) | P(beats agent.critics=1) |" in text
    assert "| success | 70.0 [60.0, 80.0] | 100.0 [100.0, 100.0] | 1.00 [1.00, 1.00] |" in text


def test_a_setting_written_as_int_or_as_float_is_one_setting(tmp_path: Path) -> None:
    runs = [make_run(tmp_path / f"r{seed}", seed, [(40, True, 0.5, None)]) for seed in (0, 1, 2)]
    for run, rate in zip(runs, (1, 1.0, 0.5)):
        plan = yaml.safe_load((run / CONFIG).read_text())
        plan["updates_per_step"] = rate
        (run / CONFIG).write_text(yaml.safe_dump(plan))
    groups = group_runs(runs)
    assert [(g.label, len(g.runs)) for g in groups] == [("updates_per_step=1", 2), ("updates_per_step=0.5", 1)]


def test_a_setting_an_older_run_lacks_reads_as_its_default_and_names_do_not_split(tmp_path: Path) -> None:
    runs = [make_run(tmp_path / f"r{seed}", seed, [(40, True, 0.5, None)]) for seed in (0, 1, 2)]
    older = yaml.safe_load((runs[0] / CONFIG).read_text())
    del older["agent"]["share_encoder"]  # trained before the setting existed
    older["name"] = "renamed"
    (runs[0] / CONFIG).write_text(yaml.safe_dump(older))
    assert [(g.label, len(g.runs)) for g in group_runs(runs)] == [("", 3)]
    changed = yaml.safe_load((runs[1] / CONFIG).read_text())
    changed["agent"]["share_encoder"] = True
    (runs[1] / CONFIG).write_text(yaml.safe_dump(changed))
    assert [(g.label, len(g.runs)) for g in group_runs(runs)] == [
        ("agent.share_encoder=false", 2),
        ("agent.share_encoder=true", 1),
    ]


def test_a_sweep_folder_stands_for_its_trials(tmp_path: Path) -> None:
    path = tiny(tmp_path)
    spec = SweepSpec.from_options(load_curriculum(path), str(path), False, ["0", "1"], [], [])
    sweep = tmp_path / "sweep"
    sweep.mkdir()
    (sweep / SWEEP_FILE).write_text(spec.to_yaml())
    for trial in spec.trials():
        make_run(sweep / trial.name, trial.seed, [(40, True, 0.5, None)])
    result = runner.invoke(app, ["report", str(sweep), "--json", "--out", str(tmp_path / "report.md")])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["groups"][0]["runs"] == [str(sweep / "seed=0"), str(sweep / "seed=1")]
    assert (tmp_path / "report.md").read_text().startswith("# Report: 2 runs")
    plot = runner.invoke(app, ["plot", str(tmp_path / "nothing")])
    assert plot.exit_code == 2 and "does not exist" in plot.output


def test_folders_that_are_no_runs_are_refused(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(ReportError, match="not a run folder"):
        make_report([tmp_path / "empty"])
    result = runner.invoke(app, ["report", str(tmp_path / "empty")])
    assert result.exit_code == 2 and "not a run folder" in result.output


def test_reporting_and_the_sweeps_display_load_neither_torch_nor_pybullet_nor_ray() -> None:
    # lanro sweep's own process imports Ray and nothing of the training, which happens in Ray's workers.
    modules = "lanrocli.report.aggregate, lanrocli.sweep.display, lanrocli.train.stop"
    code = f"import {modules}, sys; print(sorted({{'torch', 'pybullet', 'ray'}} & set(sys.modules)))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"
