"""Shipped agents: the policy alone acts as the whole agent did, names where it came from, and is found by name."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from lanrocli.cli.app import app
from lanrocli.pretrained import agent_path, export_agent, packaged_agents, provenance
from lanrocli.train.checkpoint import resolve_checkpoint
from lanrocli.train.errors import CheckpointError
from lanrocli.train.runfolder import CORRECTION_TEST, SPLITS, read_pointer, step_checkpoint
from lanrocli.train.testset import measure
from tests.train.runs import Baseline

runner = CliRunner()


def test_an_exported_policy_acts_as_the_whole_agent_and_names_its_origin(straight: Baseline, tmp_path: Path) -> None:
    source = read_pointer(straight.out / "stage-3-third" / "last")
    exported = export_agent(straight.out, tmp_path / "tiny", commit="abc1234")
    assert sum(f.stat().st_size for f in exported.iterdir()) < sum(f.stat().st_size for f in source.iterdir()) / 2
    mine, theirs = measure(exported, 2).record, measure(source, 2).record
    assert {**mine, "checkpoint": None} == {**theirs, "checkpoint": None}
    origin = provenance(exported)
    tested = json.loads((source.parent / "test.json").read_text())
    assert origin is not None and origin["commit"] == "abc1234" and origin["seed"] == 5
    assert origin["checkpoint"] == "stage-3-third/" + source.name
    assert origin["test"]["success"] == tested["last"]["success"]
    assert origin[CORRECTION_TEST]["episodes"] == tested[CORRECTION_TEST]["last"]["episodes"]
    assert set(origin) >= {f"split_{split}" for split in tested[SPLITS]}
    assert provenance(resolve_checkpoint(straight.out)) is None


def test_export_refuses_a_used_folder_and_an_untested_agent(straight: Baseline, tmp_path: Path) -> None:
    used = tmp_path / "used"
    used.mkdir()
    result = runner.invoke(app, ["export", str(straight.out), "--out", str(used), "--commit", "x"])
    assert result.exit_code == 2 and "exists" in result.output
    untested = straight.out / "stage-3-third" / step_checkpoint(200)  # kept to fall back on; never tested
    result = runner.invoke(app, ["export", str(untested), "--out", str(tmp_path / "new"), "--commit", "x"])
    assert result.exit_code == 2 and "holds no test of" in result.output


def test_a_name_finds_the_shipped_agent_and_an_unknown_one_is_named(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    for name, folder in packaged_agents().items():
        assert agent_path(Path(name)) == folder
    with pytest.raises(CheckpointError, match="no agent ships under that name"):
        agent_path(Path("no-such-agent"))
    result = runner.invoke(app, ["eval", "no-such-agent"])
    assert result.exit_code == 2 and "no agent ships under that name" in result.output


@pytest.mark.parametrize("name", sorted(packaged_agents()))
def test_every_shipped_agent_loads_and_says_where_it_came_from(name: str) -> None:
    folder = packaged_agents()[name]
    origin = provenance(folder)
    assert origin is not None and {"commit", "seed", "checkpoint", "test"} <= set(origin)
    assert sum(f.stat().st_size for f in folder.iterdir()) < 2_000_000
    record = measure(folder, 2).record
    assert record["task"] == name.split("-")[0] and record["episodes"] == 2
