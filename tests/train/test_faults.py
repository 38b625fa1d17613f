"""Faults injected on purpose, through real processes where it matters: a kill before the first checkpoint,
hostile input to ``lanro train``, two writers on one run folder, damaged checkpoint files, a checkpoint
write that fails, SIGTERM to a process group, and a trainer killed under its environment workers.

Every fault must end in one of two ways: the run continues with a command the messages name and ends
exactly as an uninterrupted run (``straight``), or a clear refusal that loses nothing."""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from typer.testing import CliRunner

from lanrocli.cli.app import app
from lanrocli.config.curriculum import load_curriculum
from lanrocli.evaluation.evaluate import SIDE_BY_SIDE
from lanrocli.train import checkpoint
from lanrocli.train import writing as runfolder
from lanrocli.train.checkpoint import AGENT_FILE, BUFFER_FILE, STATE_FILE
from lanrocli.train.errors import RunError
from lanrocli.train.pipeline import CurriculumRun
from lanrocli.train.runfolder import CONFIG, LATEST, METRICS, SET_ASIDE, read_pointer
from lanrocli.train.writing import TMP_PREFIX, RunLock
from tests.config.test_yamlfile import ALIAS_BOMB
from tests.train.runs import Baseline, finish, lanro, outcome, rows, tiny, train, wait_for_rows, wait_until

runner = CliRunner()

STOP_AT = 130
"""Where the damaged runs stopped: in the second stage, ten steps after its first evaluation, so the stage
holds two resumable checkpoints (``step-120``, ``step-130``) and the first stage two more."""


def newest(out: Path) -> Path:
    return out / "stage-2-second" / "step-0000000130"


def before_newest(out: Path) -> Path:
    return out / "stage-2-second" / "step-0000000120"


# -- a kill before the first checkpoint --------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("again", [["--resume"], []], ids=["resume", "fresh-start"])
def test_a_run_killed_before_its_first_checkpoint_goes_on_with_either_command(
    tmp_path: Path, straight: Baseline, again: list[str]
) -> None:
    out = tmp_path / "run"
    process = train([str(straight.curriculum), "--out", "run"], tmp_path)
    wait_until(lambda: (out / CONFIG).is_file(), process, "the run folder was made")
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    assert not (out / LATEST).exists(), "the kill came after the first checkpoint"

    output = finish(train([str(straight.curriculum), "--out", "run", *again], tmp_path))
    assert "starting it over" in output
    assert outcome(out) == outcome(straight.out)


def test_folders_holding_only_what_a_run_leaves_before_its_first_checkpoint_are_started_over(tmp_path: Path) -> None:
    plan = load_curriculum(tiny(tmp_path))
    for resume in (False, True):
        out = tmp_path / f"run-{resume}"
        (out / "stage-1-first" / f"{TMP_PREFIX}step-0000000040").mkdir(parents=True)
        (out / CONFIG).write_text("half a curricul")  # killed while writing: no longer possible, still harmless
        (out / METRICS).write_text("stage,stage_name\n")
        run = CurriculumRun.resume(out, plan) if resume else CurriculumRun.start(plan, out)
        try:
            assert any("starting it over" in note for note in run.notes)
            assert load_curriculum(out / CONFIG) == plan and not (out / METRICS).exists()
            assert not (out / "stage-1-first").exists()
        finally:
            run.close()


def test_resume_without_a_checkpoint_or_readable_plan_names_the_command_that_starts_over(tmp_path: Path) -> None:
    out = tmp_path / "run"
    (out / "stage-1-first").mkdir(parents=True)
    with pytest.raises(RunError, match=f"lanro train CURRICULUM --out {out}"):
        CurriculumRun.resume(out)


# -- hostile input ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["bomb", "huge"])
def test_train_refuses_a_bomb_and_a_huge_file_at_once(tmp_path: Path, name: str) -> None:
    path = tmp_path / f"{name}.yaml"
    path.write_text(ALIAS_BOMB if name == "bomb" else "name: x\n" + "# filler\n" * 1_300_000)
    started = time.monotonic()
    process = lanro(["train", str(path), "--out", "run"], tmp_path)
    output = process.communicate(timeout=60)[0]
    assert process.returncode == 2 and "Traceback" not in output, output
    assert str(path) in output and ("alias" in output if name == "bomb" else "larger than" in output)
    assert not (tmp_path / "run").exists()
    print(f"{name}: refused in {time.monotonic() - started:.1f} s")


# -- one writer ---------------------------------------------------------------------------------------------


def test_a_second_writer_is_refused_naming_the_first_and_a_dead_one_leaves_no_lock(tmp_path: Path) -> None:
    out = tmp_path / "run"
    lock = RunLock(out)
    with pytest.raises(RunError, match=f"in use: process {os.getpid()}"):
        RunLock(out)
    lock.release()
    RunLock(out).release()

    code = (
        "from pathlib import Path; from lanrocli.train.writing import RunLock; "
        f"lock = RunLock(Path({str(out)!r})); print('held', flush=True); input()"
    )
    holder = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
    with pytest.raises(RunError, match=f"in use: process {holder.pid}"):
        RunLock(out)
    holder.kill()
    holder.wait()
    RunLock(out).release()  # the kernel released the dead holder's lock


@pytest.mark.slow
def test_two_trainings_into_one_folder_one_is_refused_and_the_other_is_untouched(
    tmp_path: Path, straight: Baseline
) -> None:
    out = tmp_path / "run"
    first = train([str(straight.curriculum), "--out", "run"], tmp_path)
    wait_for_rows(out, 1, first)
    for args in ([], ["--resume"]):
        second = train([str(straight.curriculum), "--out", "run", *args], tmp_path)
        output = second.communicate(timeout=60)[0]
        assert second.returncode == 2 and f"in use: process {first.pid}" in output and "Traceback" not in output
    finish(first)
    assert outcome(out) == outcome(straight.out)


# -- damaged checkpoints --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def stopped(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The straight run's curriculum stopped at ``STOP_AT`` steps; each test damages its own copy."""
    folder = tmp_path_factory.mktemp("stopped")
    out = folder / "run"
    run = CurriculumRun.start(load_curriculum(tiny(folder, envs=2)), out)
    try:
        assert not run.run(should_stop=lambda: run.trainer.progress.env_steps >= STOP_AT)
    finally:
        run.close()
    assert read_pointer(out / LATEST) == newest(out) and before_newest(out).is_dir()
    return out


def damaged(stopped: Path, tmp_path: Path, damage: Callable[[Path], None]) -> Path:
    out = tmp_path / "run"
    shutil.copytree(stopped, out)
    damage(out)
    return out


def truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


DAMAGE: dict[str, tuple[Callable[[Path], None], int, str]] = {
    # name: (what is done to the run folder, the step the run resumes from, what the notes say)
    "truncated agent.pt": (lambda out: truncate(newest(out) / AGENT_FILE), 120, f"{AGENT_FILE} is damaged"),
    "empty agent.pt": (lambda out: (newest(out) / AGENT_FILE).write_bytes(b""), 120, f"{AGENT_FILE} is damaged"),
    "missing buffer.npz": (lambda out: (newest(out) / BUFFER_FILE).unlink(), 120, f"missing {BUFFER_FILE}"),
    "truncated buffer.npz": (lambda out: truncate(newest(out) / BUFFER_FILE), 120, f"{BUFFER_FILE} is damaged"),
    "garbage state.json": (lambda out: (newest(out) / STATE_FILE).write_text("{]"), 120, f"{STATE_FILE} is damaged"),
    "garbage latest": (lambda out: (out / LATEST).write_bytes(b"\xff\x00\n"), 130, "pointer"),
    "dangling latest": (lambda out: (out / LATEST).write_text("stage-9-none/step-1\n"), 130, "does not exist"),
    "missing metrics.csv": (lambda out: (out / METRICS).unlink(), 130, ""),
    "missing config.yaml": (lambda out: (out / CONFIG).unlink(), 130, f"{CONFIG} was missing"),
}


@pytest.mark.parametrize("name", DAMAGE)
def test_resume_survives_a_damaged_run_folder(stopped: Path, tmp_path: Path, name: str) -> None:
    damage, steps, said = DAMAGE[name]
    out = damaged(stopped, tmp_path, damage)
    run = CurriculumRun.resume(out)
    try:
        assert run.trainer.progress.env_steps == steps
        assert said in "\n".join(run.notes)
        if steps < STOP_AT:
            assert f"{STOP_AT - steps} environment steps will be trained again" in "\n".join(run.notes)
            assert (out / SET_ASIDE / "stage-2-second" / newest(out).name).is_dir() and not newest(out).exists()
            assert read_pointer(out / LATEST) == before_newest(out)
        assert rows(out) == rows(stopped)[: len(rows(out))] and int(rows(out)[-1]["env_steps"]) <= steps
        assert load_curriculum(out / CONFIG) == load_curriculum(stopped / CONFIG)
    finally:
        run.close()


@pytest.mark.slow
def test_a_run_resumed_from_an_older_checkpoint_ends_as_an_uninterrupted_one(
    stopped: Path, tmp_path: Path, straight: Baseline
) -> None:
    out = damaged(stopped, tmp_path, lambda out: truncate(newest(out) / AGENT_FILE))
    result = runner.invoke(app, ["train", "--out", str(out), "--resume"])
    assert result.exit_code == 0, result.output
    assert "damaged" in result.output and "10 environment steps will be trained again" in result.output
    assert outcome(out) == outcome(straight.out)


def test_a_folder_without_a_whole_checkpoint_is_refused_plainly(stopped: Path, tmp_path: Path) -> None:
    def damage_all(out: Path) -> None:
        for directory in out.glob("stage-*/step-*"):
            truncate(directory / AGENT_FILE)

    out = damaged(stopped, tmp_path, damage_all)
    with pytest.raises(RunError, match="no whole checkpoint") as error:
        CurriculumRun.resume(out)
    assert str(error.value).count(f"{AGENT_FILE} is damaged") == 4
    assert sorted(p.name for p in out.glob("stage-*/step-*")) == sorted(p.name for p in stopped.glob("stage-*/step-*"))


def test_a_hostile_agent_file_is_refused_as_damaged(stopped: Path, tmp_path: Path) -> None:
    import torch

    def swap(out: Path) -> None:
        state = torch.load(newest(out) / AGENT_FILE, weights_only=True)
        torch.save({**state, "note": Path("/etc/passwd")}, newest(out) / AGENT_FILE)

    out = damaged(stopped, tmp_path, swap)
    result = runner.invoke(app, ["eval", str(newest(out)), "--episodes", "1"])
    assert result.exit_code == 2 and f"{newest(out) / AGENT_FILE} is damaged" in result.output
    run = CurriculumRun.resume(out)
    run.close()
    assert run.trainer.progress.env_steps == 120


def test_eval_names_the_damaged_file(stopped: Path, tmp_path: Path) -> None:
    out = damaged(stopped, tmp_path, lambda out: truncate(newest(out) / AGENT_FILE))
    result = runner.invoke(app, ["eval", str(out), "--episodes", "1"])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"{newest(out) / AGENT_FILE} is damaged" in result.output


def test_a_read_only_run_folder_is_refused_before_anything_runs(
    stopped: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = damaged(stopped, tmp_path, lambda out: None)

    def read_only(*args: object, **kwargs: object) -> None:
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    monkeypatch.setattr(runfolder.tempfile, "TemporaryFile", read_only)
    result = runner.invoke(app, ["train", "--out", str(out), "--resume"])
    assert result.exit_code == 2 and "cannot write in the run folder" in result.output
    assert "Read-only file system" in result.output and rows(out) == rows(stopped)


# -- a checkpoint write that fails --------------------------------------------------------------------------------


def test_a_failing_checkpoint_write_stops_the_run_with_what_it_needs_and_loses_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tiny(tmp_path)
    out = tmp_path / "run"
    write_buffer = checkpoint._write_buffer
    calls = []

    def disk_full_on_the_second(target: Path, buffer: object) -> None:
        calls.append(target)
        if len(calls) == 2:
            target.write_bytes(b"x" * 100)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(target))
        write_buffer(target, buffer)  # type: ignore[arg-type]

    monkeypatch.setattr(checkpoint, "_write_buffer", disk_full_on_the_second)
    result = runner.invoke(app, ["train", str(path), "--out", str(out)])
    assert result.exit_code == 1, result.output
    message = " ".join(result.output.split())
    assert "No space left on device" in message and "It needs up to" in message and "MB are free" in message
    assert f"lanro train {path} --out {out} --resume" in message and "Traceback" not in result.output
    assert not list(out.rglob(f"{TMP_PREFIX}*")), "the failed write left its temporary files"
    assert read_pointer(out / LATEST).name == "step-0000000040"

    monkeypatch.setattr(checkpoint, "_write_buffer", write_buffer)
    resumed = runner.invoke(app, ["train", str(path), "--out", str(out), "--resume"])
    assert resumed.exit_code == 0, resumed.output
    assert [int(r["env_steps"]) for r in rows(out)] == [40, 80, 120, 160, 200, 240]


# -- signals and child processes ----------------------------------------------------------------------------------


@pytest.mark.slow
def test_sigterm_to_the_process_group_says_so_once_and_resumes_exactly(tmp_path: Path, straight: Baseline) -> None:
    out = tmp_path / "run"
    process = train([str(straight.curriculum), "--out", "run"], tmp_path)
    wait_for_rows(out, 3, process)
    os.killpg(process.pid, signal.SIGTERM)
    output = process.communicate(timeout=120)[0]
    assert process.returncode == 130 and output.count("stopping: writing a checkpoint") == 1, output
    finish(train([str(straight.curriculum), "--out", "run", "--resume"], tmp_path))
    assert outcome(out) == outcome(straight.out)


def state(pid: int) -> str:
    """The state letter of process ``pid`` in /proc ('Z' for a zombie), or 'gone'."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "gone"


def children(pid: int) -> set[int]:
    """The living child processes of ``pid``, from /proc."""
    found = set()
    for entry in Path("/proc").iterdir():
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split() if entry.name.isdigit() else []
        except OSError:
            continue
        if fields and fields[0] != "Z" and int(fields[1]) == pid:
            found.add(int(entry.name))
    return found


@pytest.mark.slow
def test_no_worker_outlives_a_killed_trainer(tmp_path: Path, straight: Baseline) -> None:
    out = tmp_path / "run"
    process = train([str(straight.curriculum), "--out", "run"], tmp_path)
    wait_for_rows(out, 1, process)
    workers = children(process.pid)
    # the two training environments, and from the first evaluation on those it plays side by side
    assert len(workers) >= 2 + SIDE_BY_SIDE, "every environment runs in a worker process"
    process.kill()  # the trainer alone, as an out-of-memory kill would
    process.wait()
    deadline = time.monotonic() + 10
    alive = workers
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = {pid for pid in workers if state(pid) not in ("Z", "gone")}
    assert not alive, f"workers {alive} outlived their trainer"
