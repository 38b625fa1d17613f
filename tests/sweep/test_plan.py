"""A sweep's definition: options read, trials named, every trial validated before anything runs, the record
in sweep.yaml and the refusal of a changed sweep. Nothing here starts Ray."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from lanrocli.cli.app import app
from lanrocli.config.curriculum import CurriculumError, load_curriculum
from lanrocli.config.overrides import SettingError
from lanrocli.sweep.plan import SWEEP_FILE, SweepError, SweepSpec, open_sweep, split_values
from tests.train.runs import tiny

runner = CliRunner()


def spec(tmp_path: Path, seeds: list[str] = (), sets: list[str] = (), grids: list[str] = ()) -> SweepSpec:
    path = tiny(tmp_path)
    return SweepSpec.from_options(load_curriculum(path), str(path), False, list(seeds), list(sets), list(grids))


def test_grid_values() -> None:
    assert split_values("1,[a,b],{x: 1, y: 2},c") == ["1", "[a,b]", "{x: 1, y: 2}", "c"]


def test_a_grid_times_the_seeds_makes_named_trials(tmp_path: Path) -> None:
    sweep = spec(tmp_path, ["0,1"], ["eval.episodes=3"], ["agent.critics=1,2", "stages[0].budget.steps=40,80"])
    trials = sweep.trials()
    assert len(trials) == 8
    assert trials[0].name == "agent.critics=1,stages.0.budget.steps=40,seed=0"
    assert trials[-1].settings == {"agent.critics": 2, "stages[0].budget.steps": 80} and trials[-1].seed == 1
    resolved = sweep.resolve()
    trial, plan = resolved[-1]
    assert (plan.agent.critics, plan.stages[0].budget.steps, plan.eval.episodes, plan.seed) == (2, 80, 3, 1)
    assert spec(tmp_path).seeds == (5,)  # the curriculum's own seed by default


def test_every_problem_of_every_trial_is_named_at_its_option(tmp_path: Path) -> None:
    sweep = spec(tmp_path, ["0,1"], ["agent.critcs=2", "stages[7].env.objects=2"], ["stages[1].budget.steps=40,-5"])
    with pytest.raises(CurriculumError) as caught:
        sweep.resolve()
    text = str(caught.value)
    assert "--set agent.critcs=2: agent.critcs: unknown key 'critcs'; did you mean 'critics'?" in text
    assert "--set stages[7].env.objects=2: stages[7]: stages has 3 items, [0] to [2]" in text
    assert "--grid stages[1].budget.steps=-5: stages[1].budget.steps: Input should be greater than 0" in text
    assert len(caught.value.problems) == 3  # each once, though two seeds share them


@pytest.mark.parametrize(
    "options, message",
    [
        ((["x"], [], []), "is not a seed"),
        ((["1", "1"], [], []), "given twice"),
        (([], ["critics"], []), "expected KEY=VALUE"),
        (([], ["seed=3"], []), "give seeds with --seeds"),
        (([], ["a.b=1"], ["a.b=2,3"]), "also with --set"),
        (([], [], ["agent.critics=1,1"]), "a value is given twice"),
    ],
)
def test_malformed_options_are_refused(tmp_path: Path, options: tuple, message: str) -> None:
    with pytest.raises((SweepError, SettingError), match=message):
        spec(tmp_path, *options)


def test_the_record_reads_back_and_a_changed_sweep_is_refused_with_a_diff(tmp_path: Path) -> None:
    sweep = spec(tmp_path, ["0", "1"], [], ["agent.critics=1,2"])
    out = tmp_path / "sweep"
    open_sweep(out, sweep, resume=False)
    saved = SweepSpec.read(out / SWEEP_FILE)
    assert saved == sweep and saved.trials() == sweep.trials()
    assert open_sweep(out, sweep, resume=True) == sweep
    assert open_sweep(out, None, resume=True) == sweep
    with pytest.raises(SweepError, match="not empty"):
        open_sweep(out, sweep, resume=False)
    other = spec(tmp_path, ["0", "2"], [], ["agent.critics=1,2"])
    with pytest.raises(SweepError, match="differs") as caught:
        open_sweep(out, other, resume=True)
    assert "-- 1\n+- 2" in str(caught.value)
    with pytest.raises(SweepError, match="no sweep to resume"):
        open_sweep(tmp_path / "none", sweep, resume=True)


def test_a_grid_with_one_bad_value_is_refused_before_anything_runs(tmp_path: Path) -> None:
    path = tiny(tmp_path)
    out = tmp_path / "sweep"
    args = ["sweep", str(path), "--out", str(out), "--seeds", "0", "1", "--grid", "agent.critics=1,3"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "--grid agent.critics=3" in result.output and "critics must be 1 or 2" in result.output
    assert not out.exists()


def test_several_values_after_one_option(tmp_path: Path) -> None:
    path = tiny(tmp_path)
    out = tmp_path / "sweep"
    # A bad value among several --set values after one option shows they were all read: nothing runs.
    args = [
        "sweep",
        str(path),
        "--seeds",
        "0",
        "1",
        "2",
        "--set",
        "eval.episodes=3",
        "agent.critics=7",
        "--out",
        str(out),
    ]
    result = runner.invoke(app, args)
    assert result.exit_code == 2 and "--set agent.critics=7" in result.output, result.output
    assert "seed=2" not in result.output and not out.exists()
