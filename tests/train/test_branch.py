"""Runs that begin where another run's stage ended (``lanro train VARIANT --from RUN``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from lanrocli.config.curriculum import load_curriculum
from lanrocli.train.branch import branch, branch_point
from lanrocli.train.errors import RunError
from lanrocli.train.pipeline import CurriculumRun
from lanrocli.train.runfolder import CONFIG
from lanrocli.train.writing import TMP_PREFIX
from tests.train.runs import Baseline, finish, outcome, tiny, train

THIRD = "negations: true, max_episode_steps: 20}\n    budget: {steps: 80}"
LONGER_THIRD = "negations: true, max_episode_steps: 20}\n    budget: {steps: 120}"


def variant(source: Path, folder: Path, old: str, new: str) -> Path:
    """A copy of the curriculum file ``source`` in ``folder`` with ``old`` replaced by ``new``."""
    text = source.read_text()
    assert old in text
    path = folder / "variant.yaml"
    path.write_text(text.replace(old, new))
    return path


def source_folder(tmp_path: Path) -> Path:
    """A run folder holding the tiny curriculum's plan, and nothing trained: enough for the checks that
    come before any checkpoint is read."""
    out = tmp_path / "source"
    out.mkdir()
    (out / CONFIG).write_text(load_curriculum(tiny(tmp_path)).to_yaml())
    return out


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("agent: {batch_size: 16}", "agent: {batch_size: 32}", r"in its stages alone(.|\n)*\+  batch_size: 32"),
        ("  - name: first\n    env: {objects: 2,", "  - name: first\n    env: {objects: 3,", "in its first stage"),
        (
            "mode: colour_shape, correction_rate",
            "mode: colour_shape, max_corrections: 2, correction_rate",
            "2 corrections",
        ),
        ("  - name: third\n", "  - name: thirds\n", "stage 2 has no checkpoint"),  # a new stage, none trained
    ],
)
def test_a_variant_that_does_not_only_change_later_stages_is_refused(
    tmp_path: Path, old: str, new: str, message: str
) -> None:
    source = source_folder(tmp_path)
    path = variant(tiny(tmp_path), tmp_path, old, new)
    with pytest.raises(RunError, match=message):
        branch(load_curriculum(path), source, tmp_path / "new")
    assert not (tmp_path / "new").exists()


def test_a_variant_that_judges_its_last_stage_otherwise_branches_there(tmp_path: Path) -> None:
    path = variant(tiny(tmp_path), tmp_path, THIRD, THIRD + "\n    eval: {correction_rate: 1}")
    assert branch_point(load_curriculum(tiny(tmp_path)), load_curriculum(path)) == 2


def test_a_variant_that_samples_its_last_stage_otherwise_branches_there(tmp_path: Path) -> None:
    path = variant(tiny(tmp_path), tmp_path, THIRD, THIRD + "\n    buffer: {fresh_targets: true}")
    assert branch_point(load_curriculum(tiny(tmp_path)), load_curriculum(path)) == 2


def test_the_same_curriculum_has_nothing_to_branch_into(tmp_path: Path) -> None:
    with pytest.raises(RunError, match="no stage after the run's first 3"):
        branch(load_curriculum(tiny(tmp_path)), source_folder(tmp_path), tmp_path / "new")


def test_a_stage_that_has_not_ended_is_not_branched_from(tmp_path: Path) -> None:
    path = tiny(tmp_path)
    source = tmp_path / "source"
    run = CurriculumRun.start(load_curriculum(path), source)
    run.run(should_stop=lambda: run.trainer.progress.env_steps >= 100)  # inside the second stage (80 to 160)
    run.close()
    with pytest.raises(RunError, match=r"stage 2 \(second\) has not ended yet(.|\n)*--resume --out"):
        branch(load_curriculum(variant(path, tmp_path, THIRD, LONGER_THIRD)), source, tmp_path / "new")
    assert not (tmp_path / "new").exists() or not any(p.name != ".lock" for p in (tmp_path / "new").iterdir())


@pytest.mark.slow
def test_a_branched_run_stopped_and_resumed_ends_as_the_variant_run_from_its_first_step(
    tmp_path: Path, straight: Baseline
) -> None:
    path = variant(straight.curriculum, tmp_path, THIRD, LONGER_THIRD)
    finish(train([str(path), "--out", "scratch"], tmp_path))

    leftover = tmp_path / "branched" / f"{TMP_PREFIX}stage-1-first"  # what a branch killed while copying leaves
    leftover.mkdir(parents=True)
    (leftover / "test.json").write_text("{")
    run = branch(load_curriculum(path), straight.out, tmp_path / "branched")
    assert run.state.stage == 2 and run.trainer.progress.env_steps == 160
    run.run(should_stop=lambda: run.trainer.progress.env_steps >= 190)
    run.close()
    finish(train([str(path), "--out", "branched", "--resume"], tmp_path))

    assert outcome(tmp_path / "branched") == outcome(tmp_path / "scratch") and not leftover.exists()
    assert load_curriculum(tmp_path / "branched" / CONFIG) == load_curriculum(path)


@pytest.mark.slow
def test_a_stage_added_after_a_run_ended_goes_on_as_the_variant_run_from_its_first_step(
    tmp_path: Path, straight: Baseline
) -> None:
    fourth = "  - name: fourth\n    env: {objects: 2, max_episode_steps: 15}\n    budget: {steps: 40}\nholdout:"
    path = tmp_path / "fourth.yaml"
    path.write_text(straight.curriculum.read_text().replace("holdout:", fourth))
    finish(train([str(path), "--out", "scratch"], tmp_path))
    output = finish(train([str(path), "--from", str(straight.out), "--out", "continued"], tmp_path))

    assert "began at stage 4" in output
    (metrics, stages, tests), scratch = outcome(tmp_path / "continued"), outcome(tmp_path / "scratch")
    assert (metrics, stages) == scratch[:2] and [name for name, *_ in stages][-1] == "fourth"
    # The fourth stage's agents measured alike; the third, copied, keeps the tests it had as the run's last.
    assert tests[3] == scratch[2][3] and "correction_test" in tests[2] and "correction_test" not in scratch[2][2]


def test_a_run_stopped_by_its_budget_is_not_continued(tmp_path: Path) -> None:
    source = tmp_path / "source"
    rule = "promote: {success: 1.0"
    stop = variant(tiny(tmp_path), tmp_path, rule + "}", rule + ", patience: 2}\n    on_budget: stop")
    run = CurriculumRun.start(load_curriculum(stop), source)
    run.run()
    run.close()
    assert run.state.stopped_early  # its rule asks for every episode of two evaluations won
    second = "correction_rate: 0.5, max_episode_steps: 20}\n    budget: {steps: "
    longer = variant(stop, tmp_path, second + "80}", second + "120}")
    with pytest.raises(RunError, match=r"stopped when the budget of its stage 1 ran out(.|\n)*stops there too"):
        branch(load_curriculum(longer), source, tmp_path / "new")


def test_the_cli_refuses_from_with_resume(tmp_path: Path) -> None:
    process = train([str(tiny(tmp_path)), "--from", "elsewhere", "--resume"], tmp_path)
    output = process.communicate(timeout=60)[0]
    assert process.returncode == 2 and "--from starts a new run" in output
