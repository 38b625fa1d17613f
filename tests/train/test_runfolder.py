"""The run folder's files: pointers and pruning, metrics.csv on resume, writes that leave nothing half done."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from lanrocli.train.report import correction_test_lines
from lanrocli.train.runfolder import (
    BEST,
    LAST,
    LATEST,
    METRIC_COLUMNS,
    METRICS,
    align_metrics,
    append_metrics,
    publish,
    read_pointer,
    truncate_metrics,
)
from lanrocli.train.writing import write_json


def test_publishing_points_at_the_new_checkpoints_and_prunes_all_but_the_one_before(tmp_path: Path) -> None:
    folder = tmp_path / "stage-1-first"
    for name in ("step-1", "best-1", ".tmp-step-2"):
        (folder / name).mkdir(parents=True)
    publish(tmp_path, folder / "step-1", folder / "best-1")
    assert {p.name for p in folder.iterdir() if p.is_dir()} == {"step-1", "best-1"}
    (folder / "step-2").mkdir()
    publish(tmp_path, folder / "step-2", None)  # the stage's best stays where it was
    assert read_pointer(folder / LAST) == folder / "step-2" and read_pointer(folder / BEST) == folder / "best-1"
    assert read_pointer(tmp_path / LATEST) == folder / "step-2"
    assert {p.name for p in folder.iterdir() if p.is_dir()} == {"step-1", "step-2", "best-1"}
    for name in ("step-3", "best-3"):
        (folder / name).mkdir()
    publish(tmp_path, folder / "step-3", folder / "best-3")
    assert {p.name for p in folder.iterdir() if p.is_dir()} == {"step-2", "step-3", "best-3"}
    assert {p.name for p in folder.iterdir() if p.is_file()} == {LAST, BEST}  # no pointer left half written


def test_metrics_written_after_the_resumed_checkpoint_are_dropped(tmp_path: Path) -> None:
    path = tmp_path / "metrics.csv"
    for steps in (40, 80, 120):
        append_metrics(path, {"stage": 1, "stage_name": "first", "env_steps": steps})
    truncate_metrics(path, 80)
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames or ()) == METRIC_COLUMNS
        assert [int(r["env_steps"]) for r in reader] == [40, 80]
    assert [p.name for p in tmp_path.iterdir()] == ["metrics.csv"]
    truncate_metrics(tmp_path / "none.csv", 80)  # a run stopped before its first evaluation has none
    assert not (tmp_path / "none.csv").exists()


def test_json_is_replaced_whole(tmp_path: Path) -> None:
    path = tmp_path / "test.json"
    write_json(path, {"last": 1})
    write_json(path, {"last": 2})
    assert json.loads(path.read_text()) == {"last": 2} and [p.name for p in tmp_path.iterdir()] == ["test.json"]


def test_a_metrics_file_of_an_older_version_gains_the_new_columns_and_still_plots(tmp_path: Path) -> None:
    from lanrocli.report.plot import read_run

    # An older version wrote fewer columns, one of them ("correction_success") no longer written.
    old = ["stage", "stage_name", "env_steps", "success", "correction_success", "corrected_episodes_negation"]
    path = tmp_path / METRICS
    path.write_text(",".join(old) + "\n1,first,40,0.5,0.25,3\n")
    append_metrics(
        path, {"stage": 1, "stage_name": "first", "env_steps": 80, "success": 0.75, "corrected_success": 1.0}
    )
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
        assert list(reader.fieldnames or ()) == [*METRIC_COLUMNS, "correction_success"]
    assert [r["success"] for r in rows] == ["0.5", "0.75"]
    assert (rows[0]["correction_success"], rows[0]["corrected_episodes_negation"], rows[0]["corrected_success"]) == (
        "0.25",
        "3",
        "",
    )
    assert rows[1]["corrected_success"] == "1.0"
    assert read_run(tmp_path).steps.tolist() == [40, 80]
    assert align_metrics(path) == []  # once aligned, the file is left alone


def test_aligning_names_the_columns_gained(tmp_path: Path) -> None:
    path = tmp_path / METRICS
    path.write_text(",".join(c for c in METRIC_COLUMNS if not c.endswith("_edit")) + "\n")
    assert align_metrics(path) == ["corrected_episodes_edit", "corrected_success_edit", "attention_on_goal_edit"]
    assert align_metrics(tmp_path / "none.csv") == []


def correction_record(agent: str, spoken: int, negations: int) -> dict:
    rate = lambda n, s: {"episodes": n, "success": s, "ci": [0.0, 1.0]}  # noqa: E731
    return {
        "checkpoint": f"stage-3-third/{agent}-0000000240",
        "episodes": 400,
        "quota_met": True,
        "quota": {"spoken": 300, "negations": 150, "episodes": 3000},
        "corrected": rate(spoken, 0.5),
        "by_kind": {
            "ambiguity": {**rate(200, 0.4), "corrected": rate(spoken - 20, 0.5)},
            "common_ground": {**rate(30, 0.4), "corrected": rate(20, 0.25)},
        },
        "by_form": {"excuse": rate(spoken - negations, 0.6), "negation": rate(negations, 0.4), "edit": rate(0, None)},
        "attention_on_goal": {"plain": 0.5, "excuse": 0.75, "negation": None, "edit": None},
    }


def test_report_md_shows_the_correction_test_and_marks_what_is_not_judged() -> None:
    lines = correction_test_lines({"last": correction_record("step", 300, 150)})
    text = "\n".join(lines)
    assert "## Correction test" in text and "until 300 corrections and 150 negations were spoken" in text
    (header,) = [line for line in lines if line.startswith("| agent | episodes")]
    row = next(line for line in lines if line.startswith("| last ("))
    cells = dict(zip(*([cell.strip() for cell in line.strip("|").split("|")] for line in (header, row))))
    assert cells["ambiguity"] == "50% (280)" and cells["common ground"] == "25% (20)*"
    assert cells["after a negation"] == "40% (150)" and cells["after an edit"] == "-"
    assert "| last | 0.50 | 0.75 | - | - |" in lines
