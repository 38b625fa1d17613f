"""The run folder's files: pointers and pruning, metrics.csv on resume, writes that leave nothing half done."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from lanrocli.train.runfolder import (
    BEST,
    LAST,
    LATEST,
    METRIC_COLUMNS,
    append_metrics,
    publish,
    read_pointer,
    truncate_metrics,
    write_json,
)


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
