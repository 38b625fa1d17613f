"""A figure added to the registry, as the recipe "add a metric" in docs/architecture.md has it: a run
written without it is resumed with it, and ``lanro plot`` and ``lanro report`` read what it became."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from lanrocli.cli.app import app
from lanrocli.config.curriculum import load_curriculum
from lanrocli.evaluation.metrics import FIGURES, METRIC_NAMES, Figure
from lanrocli.train.pipeline import CurriculumRun
from lanrocli.train.runfolder import METRIC_COLUMNS
from tests.train.runs import rows

ONE_STAGE = """\
name: one-stage
task: reach
seed: 3
envs: 1
learning_starts: 40
agent: {batch_size: 16}
buffer: {size: 4000}
eval: {every: 40, episodes: 2}
test: {episodes: 2}
stages:
  - name: only
    env: {objects: 2, max_episode_steps: 15}
    budget: {steps: 80}
"""

QUICK = Figure("quick_success", "quick_episodes", "within ten steps", lambda r: r.length <= 10, ("quick",))
"""Episodes that ended within ten steps, and the share of them won."""


def test_a_run_resumed_with_a_new_figure_keeps_its_rows_and_is_read_by_plot_and_report(tmp_path: Path) -> None:
    path, out = tmp_path / "one-stage.yaml", tmp_path / "run"
    path.write_text(ONE_STAGE)
    run = CurriculumRun.start(load_curriculum(path), out)
    run.run(should_stop=lambda: run.trainer.progress.env_steps >= 50)
    run.close()
    (before,) = rows(out)
    assert "quick_success" not in before

    with FIGURES.registered(QUICK):
        assert "quick_success" in METRIC_NAMES
        resumed = CurriculumRun.resume(out, load_curriculum(path))
        assert resumed.run()
        resumed.close()
        old, new = rows(out)
        assert list(new) == list(METRIC_COLUMNS)  # the header gained the figure's columns, in registry order
        assert old == before | {"quick_episodes": "", "quick_success": ""}  # the old row kept, its new cells empty
        assert new["quick_episodes"] != "" and int(new["quick_episodes"]) <= int(new["episodes"])

    runner = CliRunner()
    plot = runner.invoke(app, ["plot", str(out), "--out", str(tmp_path / "curves.png")])
    assert plot.exit_code == 0, plot.output
    assert (tmp_path / "curves.png").stat().st_size > 0
    report = runner.invoke(app, ["report", str(out), "--json"])
    assert report.exit_code == 0, report.output
    (group,) = json.loads(report.output)["groups"]
    assert group["runs"] == [str(out)] and group["ended"] == 1
    assert [stage["name"] for stage in group["stages"]] == ["only"] and "success" in group["stages"][0]["metrics"]
    assert "quick_success" not in METRIC_COLUMNS  # the figure left the registry with its block
