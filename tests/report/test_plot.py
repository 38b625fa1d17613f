"""Plotting run folders: reading metrics.csv, damaged ones refused at their line, and no torch or pybullet."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from lanrocli.cli.app import app
from lanrocli.report.plot import mean_and_band, median_boundaries, plot_groups, read_run
from lanrocli.train.runfolder import METRIC_COLUMNS, METRICS


def test_plotting_loads_neither_torch_nor_pybullet() -> None:
    # A fresh interpreter: in this one, other tests have loaded both long ago.
    code = "import lanrocli.report.plot; import sys; print(sorted({'torch', 'pybullet'} & set(sys.modules)))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]", f"importing lanrocli.report.plot loaded {result.stdout.strip()}"


def metrics_line(stage: int, env_steps: object, success: object = 0.5) -> str:
    """One row of ``metrics.csv`` as ``lanro train`` appends it, the columns a plot does not read empty."""
    values = dict.fromkeys(METRIC_COLUMNS, "")
    values.update(stage=stage, stage_name=f"stage-{stage + 1}", env_steps=env_steps, success=success)
    return ",".join(str(values[column]) for column in METRIC_COLUMNS)


HEADER = ",".join(METRIC_COLUMNS)


def run_folder(tmp_path: Path, *lines: str) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    (run / METRICS).write_text("".join(line + "\n" for line in lines))
    return run


def test_a_run_folder_reads_as_its_curve(tmp_path: Path) -> None:
    run = run_folder(tmp_path, HEADER, metrics_line(0, 100, 0.25), "", metrics_line(0, 200), metrics_line(1, 300, 1))
    curve = read_run(run)
    assert curve.name == "run" and curve.steps.tolist() == [100, 200, 300]
    assert curve.values["success"].tolist() == [0.25, 0.5, 1.0] and np.isnan(curve.values["corrected_success"]).all()
    assert curve.boundaries == [(200, "stage-2")]


DAMAGED = {
    "garbled line": ((HEADER, metrics_line(0, 100), "0,stage-1,20", metrics_line(0, 300)), 3, "3 values where"),
    "not a number": (
        (HEADER, metrics_line(0, 100), metrics_line(0, 200, "half")),
        3,
        "success is 'half', not a number",
    ),
    "steps not whole": ((HEADER, metrics_line(0, 1.5)), 2, "env_steps is '1.5', not a whole number"),
    "missing header": ((metrics_line(0, 100), metrics_line(0, 200)), 1, "the header has no columns"),
}


@pytest.mark.parametrize("damage", DAMAGED)
def test_a_damaged_metrics_file_is_an_error_at_its_line(tmp_path: Path, damage: str) -> None:
    lines, line, message = DAMAGED[damage]
    run = run_folder(tmp_path, *lines)
    with pytest.raises(ValueError) as caught:
        read_run(run)
    assert str(caught.value).startswith(f"{run / METRICS}:{line}: ") and message in str(caught.value)
    result = CliRunner().invoke(app, ["plot", str(run), "--out", str(tmp_path / "curves.png")])
    assert result.exit_code == 2 and f"{run / METRICS}:{line}" in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert not (tmp_path / "curves.png").exists()


def test_a_metrics_file_that_is_not_text_is_an_error_at_its_line(tmp_path: Path) -> None:
    run = run_folder(tmp_path, HEADER, metrics_line(0, 100))
    with open(run / METRICS, "ab") as file:
        file.write(b"\xff\xfe\x00\x01\n")
    with pytest.raises(ValueError, match=f"{METRICS}:3: not UTF-8"):
        read_run(run)


def test_groups_are_drawn_as_mean_and_bootstrap_band_with_median_boundaries(tmp_path: Path) -> None:
    runs = []
    for name, boundary, success in (("a", 200, 0.2), ("b", 300, 0.4), ("c", 400, 0.9)):
        folder = tmp_path / name
        folder.mkdir()
        lines = [
            HEADER,
            metrics_line(0, 100, success),
            metrics_line(0, boundary, success),
            metrics_line(1, 500, success),
        ]
        (folder / METRICS).write_text("".join(line + "\n" for line in lines))
        runs.append(folder)
    curves = [read_run(run) for run in runs]
    assert median_boundaries(curves) == [(300.0, "stage-2")]
    steps, mean, low, high = mean_and_band(curves, "success")
    assert steps.tolist() == [100, 200, 300, 400, 500]
    assert mean[0] == pytest.approx(0.5) and low[0] == pytest.approx(0.2) and high[0] == pytest.approx(0.9)
    one = mean_and_band(curves[:1], "success")
    assert one[1][0] == one[2][0] == one[3][0] == 0.2  # one run: no band
    out = plot_groups([("x=1", runs[:2]), ("x=2", runs[2:])], tmp_path / "groups.png")
    assert out.stat().st_size > 10_000
