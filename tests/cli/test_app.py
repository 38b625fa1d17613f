"""The ``lanro`` command line, driven through typer's CliRunner."""

from __future__ import annotations

import inspect
import json
import os
import re
from pathlib import Path

import pytest
import torch
import typer
from typer.testing import CliRunner

from lanrocli import __version__
from lanrocli.cli.app import app
from lanrocli.language import grammar_vocabulary

runner = CliRunner()

QUICK = Path(__file__).parents[2] / "lanrocli" / "curricula" / "quick.yaml"
"""The curriculum ``lanro train --quick`` runs without a file."""


def test_help_lists_commands() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    assert "sample-instructions" in result.output


def test_version() -> None:
    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0 and __version__ in result.output


COMMANDS = sorted(typer.main.get_command(app).commands)  # type: ignore[attr-defined]


@pytest.mark.parametrize("command", [[], *([name] for name in COMMANDS)], ids=lambda c: " ".join(c) or "lanro")
def test_help_labels_the_options_that_take_a_value_and_no_flag(command: list[str]) -> None:
    result = runner.invoke(app, [*command, "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "--help" in result.output and "<bool>" not in result.output
    if command == ["eval"]:
        assert "<int range>" in result.output and "<path>" in result.output


def test_every_command_is_summed_up_in_one_unbroken_line() -> None:
    """``lanro --help`` shows the first paragraph of each command's help with its line breaks kept."""
    for name, command in typer.main.get_command(app).commands.items():  # type: ignore[attr-defined]
        summary = inspect.cleandoc(command.help or "").split("\n\n")[0]
        assert summary and "\n" not in summary, f"lanro {name}: {summary!r}"


def test_eval_help_names_every_kind_of_correction_whole() -> None:
    from lanrocli.core.choices import Kind

    result = runner.invoke(app, ["eval", "--help"], env={"COLUMNS": "100"})
    assert all(re.search(rf"\b{kind}\b", result.output) for kind in Kind), result.output


@pytest.mark.parametrize(
    "command", [["eval", "oracle"], ["train", "--quick", "--out", "never"], ["play", "no-such-run"]], ids=lambda c: c[0]
)
def test_every_command_refuses_an_unknown_device_by_name(command: list[str], tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, [*command, "--device", "gpu0"])
    assert result.exit_code == 2, result.output
    assert "--device 'gpu0' is not a device lanro runs on; use cpu, cuda or cuda:N" in result.output
    assert not (tmp_path / "never").exists()


def test_play_states_one_episode_limit() -> None:
    from lanrocli.envs.settings import CORRECTION_LIMIT, PLAIN_LIMIT

    play = typer.main.get_command(app).commands["play"]  # type: ignore[attr-defined]
    (limit,) = [param.help for param in play.params if param.name == "max_episode_steps"]
    assert f"default: {CORRECTION_LIMIT}" in limit and str(PLAIN_LIMIT) not in limit
    assert str(CORRECTION_LIMIT) not in (play.help or ""), "the limit is stated by the option alone"


def test_shell_completion_completes_commands_and_options() -> None:
    import subprocess
    import sys

    def complete(words: str) -> list[str]:
        cword = str(len(words.split()) - 1)
        env = {**os.environ, "_LANRO_COMPLETE": "complete_bash", "COMP_WORDS": words, "COMP_CWORD": cword}
        code = "from lanrocli.cli.app import app; app(prog_name='lanro')"
        result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        return result.stdout.split()

    assert complete("lanro tr") == ["train"]
    assert "--correction-rate" in complete("lanro eval --corr")
    assert "--install-completion" in runner.invoke(app, ["--help"]).output


def test_sample_json_is_reproducible_and_well_formed() -> None:
    args = [
        "sample-instructions",
        "--task",
        "push",
        "--n",
        "25",
        "--seed",
        "4",
        "--corrections",
        "--negations",
        "--json",
    ]
    first = runner.invoke(app, args)
    second = runner.invoke(app, args)
    assert first.exit_code == 0 and first.output == second.output
    items = json.loads(first.output)
    assert len(items) == 25
    vocab = grammar_vocabulary()
    for item in items:
        assert set(item) == {"instruction", "correction", "text", "tokens"}
        assert item["instruction"].split()[0] in {"push", "move", "shift"}
        assert item["text"] == f"{item['instruction']} {item['correction']}"
        assert vocab.decode(item["tokens"]) == item["text"]
    other = runner.invoke(app, [*args[:-2], "--seed", "5", "--json"])
    assert other.output != first.output


def test_sample_without_corrections_has_null_correction() -> None:
    items = json.loads(runner.invoke(app, ["sample-instructions", "--n", "5", "--json"]).output)
    assert all(i["correction"] is None and i["text"] == i["instruction"] for i in items)


def test_table_output() -> None:
    result = runner.invoke(app, ["sample-instructions", "--task", "lift", "--n", "3"])
    assert result.exit_code == 0 and "lift: 3 sampled sentences" in result.output


def test_a_split_shows_what_the_instructor_says_in_its_episodes() -> None:
    result = runner.invoke(
        app, ["sample-instructions", "--task", "push", "--split", "paraphrase", "--n", "6", "--json"]
    )
    assert result.exit_code == 0, result.output
    spoken = json.loads(result.output)
    assert len(spoken) == 6 and all(s["phrasing"] for s in spoken)
    refused = runner.invoke(app, ["sample-instructions", "--split", "paraphrase", "--corrections"])
    assert refused.exit_code == 2 and "--split" in refused.output


def test_all_enumerates_every_instruction() -> None:
    result = runner.invoke(app, ["sample-instructions", "--all", "--task", "grasp"])
    lines = result.output.strip().splitlines()
    assert result.exit_code == 0 and len(lines) == len(set(lines)) == 3 * 99


def test_stats_match_hand_counts() -> None:
    result = runner.invoke(
        app, ["sample-instructions", "--all", "--corrections", "--negations", "--rare", "--stats", "--json"]
    )
    stats = json.loads(result.output)
    # 3 verbs x (27 colour words x 9 shape words + 9 shape words + 27 colour words) = 837 instructions;
    # 6 beginnings x (9 x 9 + 9 + 9) = 594 corrections.
    assert stats["sentences"] == stats["distinct_sentences"] == 837 * 594
    assert stats["vocabulary_size"] == 61 and stats["max_length"] == 10
    assert stats["by_form"] == {"colour_shape": 729 * 594, "shape": 27 * 594, "colour": 81 * 594}
    assert stats["by_beginning"] == {"excuse": 837 * 4 * 99, "negation": 837 * 99, "edit": 837 * 99}


def test_bad_task_is_a_clear_error() -> None:
    result = runner.invoke(app, ["sample-instructions", "--task", "fly"])
    assert result.exit_code == 2 and "fly" in result.output and "--task" in result.output


def test_negative_n_is_a_clear_error() -> None:
    result = runner.invoke(app, ["sample-instructions", "--n", "-1"])
    assert result.exit_code == 2 and "--n" in result.output


def test_negations_without_corrections_is_refused() -> None:
    result = runner.invoke(app, ["sample-instructions", "--negations"])
    assert result.exit_code == 2 and "--corrections" in result.output


def test_eval_json_is_clean_on_the_real_stdout() -> None:
    """PyBullet's native code prints on fd 1; the JSON output must still parse."""
    import subprocess
    import sys

    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "from lanrocli.cli.app import app; app()",
            "eval",
            "oracle",
            "--episodes",
            "2",
            "--json",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    report = json.loads(out.stdout)
    assert report["episodes"] == 2 and report["policy"] == "oracle"


def test_eval_table_and_bad_values() -> None:
    result = runner.invoke(app, ["eval", "random", "--task", "push", "--episodes", "2", "--correction-rate", "0.5"])
    assert result.exit_code == 0 and "correction episodes" in result.output
    bad = runner.invoke(app, ["eval", "oracle", "--correction-rate", "1.5"])
    assert bad.exit_code == 2 and "--correction-rate" in bad.output
    bad = runner.invoke(app, ["eval", "oracle", "--correction-rate", "0.5", "--kinds", "gossip"])
    assert bad.exit_code == 2
    bad = runner.invoke(app, ["eval", "telepath"])
    assert bad.exit_code == 2
    bad = runner.invoke(app, ["eval", "oracle", "--instruction", "blank"])
    assert bad.exit_code == 2 and "scripted policies read no sentence" in bad.output
    bad = runner.invoke(app, ["eval", "oracle", "--task", "push", "--object-start", "0.5"])
    assert bad.exit_code == 2 and "object_start is 0.5, but it needs a task with a gripper" in bad.output


def test_bad_worker_counts_and_uses_are_refused_before_anything_runs(tmp_path) -> None:
    for args, words in (
        (["train", "--quick", "--out", str(tmp_path / "run"), "--workers", "0"], "--workers"),
        (["eval", "push", "--workers", "0"], "--workers"),
        (["eval", "push", "--workers", "2", "--gif", str(tmp_path / "a.gif")], "records its frames in this process"),
        (["eval", "push", "--address", "auto"], "add --protocol"),
        (["eval", "oracle", "--workers", "2"], "add --protocol"),
    ):
        refused = runner.invoke(app, args)
        assert refused.exit_code == 2 and words in " ".join(refused.output.split()), (args, refused.output)
    assert not (tmp_path / "run").exists()


def test_eval_writes_a_gif(tmp_path) -> None:
    gif = tmp_path / "episodes.gif"
    result = runner.invoke(app, ["eval", "oracle", "--episodes", "1", "--gif", str(gif)])
    assert result.exit_code == 0 and gif.stat().st_size > 1000


@pytest.mark.slow
def test_quick_training_run_then_eval_plot_and_refusals(tmp_path) -> None:
    """The README's first command on its built-in curriculum, scaled down further (``quick.yaml --quick``, its
    tests on four episodes, which scales the correction test too) to keep the suite short, and what can be
    done with its run folder."""
    out = tmp_path / "run"
    quick = ["train", str(QUICK), "--quick", "--set", "test.episodes=4", "--out", str(out)]
    result = runner.invoke(app, quick)
    assert result.exit_code == 0, result.output
    for command in (f"lanro eval {out}", f"lanro plot {out} --out curves.png", f"lanro play {out}"):
        assert command in result.output  # what to try next, with the run folder filled in
    for name in ("config.yaml", "metrics.csv", "report.md", "latest"):
        assert (out / name).is_file()
    for stage in ("stage-1-single", "stage-2-corrections", "stage-3-negations"):
        assert (out / stage / "best").is_file() and (out / stage / "last").is_file()
    report_text = (out / "report.md").read_text()
    assert "Status: finished" in report_text

    assert "## Test: held-out episodes" in report_text and "## Language check" in report_text
    tested = json.loads((out / "stage-3-negations" / "test.json").read_text())
    assert set(tested) == {"last", "best", "language", "correction_test"}
    assert set(tested["language"]) == {"true", "blank", "other"} and set(tested["correction_test"]) == {"last", "best"}
    blank = tested["language"]["blank"]
    assert (
        blank["named_first"]["episodes"] == blank["episodes"]
        and "| instruction | success | named object first |" in report_text
    )
    assert "## Correction test" in report_text
    corrections = runner.invoke(app, ["eval", str(out), "--correction-test", "--json"])
    assert corrections.exit_code == 0, corrections.output
    assert json.loads(corrections.output) == tested["correction_test"]["last"]  # the run's figures, again

    evaluated = runner.invoke(app, ["eval", str(out), "--json"])
    assert evaluated.exit_code == 0, evaluated.output
    report = json.loads(evaluated.output)
    # By default a checkpoint meets its stage's test episodes, so its numbers are report.md's.
    assert report == tested["last"]
    assert report["env"]["objects"] == 2 and report["env"]["negations"] is True
    assert set(report["corrected"]) == {"episodes", "success", "ci"}
    others = json.loads(runner.invoke(app, ["eval", str(out), "--episodes", "3", "--seed", "5", "--json"]).output)
    assert others["episodes"] == 3 and others["episodes_from"] == {"test_set": False, "first_seed": 5}
    blank = runner.invoke(app, ["eval", str(out), "--instruction", "blank", "--correction-rate", "0", "--json"])
    assert json.loads(blank.output) == tested["language"]["blank"]
    best = runner.invoke(app, ["eval", str(out / "stage-1-single" / "best"), "--episodes", "2"])
    assert best.exit_code == 0 and "2 objects, colour" in best.output
    assert runner.invoke(app, ["eval", str(out), "--task", "reach"]).exit_code == 2

    plot = runner.invoke(app, ["plot", str(out), "--out", str(tmp_path / "curves.png")])
    assert plot.exit_code == 0 and (tmp_path / "curves.png").stat().st_size > 10_000

    again = runner.invoke(app, quick)
    assert again.exit_code == 2 and "--resume" in again.output
    changed = runner.invoke(app, [*quick, "--resume", "--seed", "7"])
    assert changed.exit_code == 2 and "-seed: 0" in changed.output and "+seed: 7" in changed.output
    unscaled = runner.invoke(app, ["train", "--quick", "--out", str(out), "--resume"])
    assert unscaled.exit_code == 2 and "+name: push-quick\n" in unscaled.output  # the built-in file as written
    finished = runner.invoke(app, [*quick, "--resume"])
    assert finished.exit_code == 0 and "finished already" in finished.output


def test_every_shipped_curriculum_checks(tmp_path) -> None:
    from pathlib import Path

    files = sorted(Path(__file__).parents[2].joinpath("curricula").glob("*.yaml"))
    assert {f.stem for f in files} >= {"reach", "push", "grasp", "lift"}
    for path in files:
        result = runner.invoke(app, ["check", str(path)])
        assert result.exit_code == 0, result.output
        assert "environment steps in all" in result.output


def test_check_names_the_stages_that_sample_otherwise(tmp_path: Path) -> None:
    screen = tmp_path / "screen.yaml"
    screen.write_text(QUICK.read_text() + "    buffer: {fresh_targets: false}\n")
    result = runner.invoke(app, ["check", str(screen)], terminal_width=200)
    assert result.exit_code == 0, result.output
    assert "stage 3 (negations) samples with {'fresh_targets': False}" in result.output
    assert "stage 2 (corrections) samples" not in result.output


def test_quick_without_a_file_runs_quick_yaml_as_written_and_with_a_file_scales_it() -> None:
    from lanrocli.cli.arguments import load_plan as _load_plan
    from lanrocli.config.curriculum import builtin_curriculum, load_curriculum

    written = load_curriculum(QUICK)
    assert _load_plan(None, True, None, None) == builtin_curriculum() == written
    assert _load_plan(QUICK, True, None, None) == written.quick() != written
    assert _load_plan(None, True, 3, 4) == written.with_overrides(seed=3, envs=4)

    builtin = runner.invoke(app, ["check", "--quick"])
    assert builtin.exit_code == 0, builtin.output
    assert builtin.output == runner.invoke(app, ["check", str(QUICK)]).output
    scaled = runner.invoke(app, ["check", str(QUICK), "--quick"])
    assert scaled.exit_code == 0 and f"{written.name}-quick:" in scaled.output


def test_packaged_curricula_by_name_from_any_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from lanrocli.config.curriculum import packaged_curricula

    monkeypatch.chdir(tmp_path)
    named = runner.invoke(app, ["check", "reach"])
    assert named.exit_code == 0, named.output
    assert named.output == runner.invoke(app, ["check", str(packaged_curricula()["reach"])]).output
    listed = runner.invoke(app, ["check"])
    assert listed.exit_code == 0, listed.output
    assert all(f"│ {name} " in listed.output for name in packaged_curricula())
    for command in (["check", "pushh"], ["train", "pushh"]):
        unknown = runner.invoke(app, command)
        assert unknown.exit_code == 2, unknown.output
        assert (
            "pushh: no such file" in unknown.output
            and "grasp, lift, push, push-ask, quick, reach, reach-ask" in unknown.output
        )
    assert not (tmp_path / "checkpoints").exists()


def test_set_changes_the_plan_of_check_and_train_and_a_bad_key_is_located(tmp_path: Path) -> None:
    shown = runner.invoke(app, ["check", "quick", "--set", "eval.episodes=7", "stages[0].budget.steps=99"])
    assert shown.exit_code == 0, shown.output
    assert "7 fresh episodes" in shown.output and "99 steps" in shown.output
    out = tmp_path / "run"
    for command in (["check", "quick"], ["train", "quick", "--out", str(out)]):
        bad = runner.invoke(app, [*command, "--set", "eval.episodes=3", "agent.critcs=2"])
        assert bad.exit_code == 2, bad.output
        assert "--set agent.critcs=2: agent.critcs: unknown key 'critcs'; did you mean 'critics'?" in bad.output
        malformed = runner.invoke(app, [*command, "--set", "critics"])
        assert malformed.exit_code == 2 and "--set critics: expected KEY=VALUE" in malformed.output
    assert not out.exists()
    alone = runner.invoke(app, ["check", "--set", "eval.episodes=3"])
    assert alone.exit_code == 2 and "--set needs the curriculum" in alone.output


def test_check_reports_every_problem_with_its_place_and_exits_2(tmp_path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(
        "name: bad\ntask: reach\nstages:\n  - name: one\n    env: {objects: 2, corection_rate: 0.5}\n"
        "    budget: {steps: 100}\n  - name: two\n    env: {correction_rate: 1.5}\n    budget: {steps: -1}\n"
    )
    result = runner.invoke(app, ["check", str(path)])
    assert result.exit_code == 2
    assert "3 problems" in result.output
    assert (
        f"{path}:5: stages[0].env.corection_rate" in result.output and "did you mean 'correction_rate'" in result.output
    )
    assert f"{path}:8: stages[1].env.correction_rate" in result.output
    assert f"{path}:9: stages[1].budget.steps" in result.output
    missing = runner.invoke(app, ["train"])
    assert missing.exit_code == 2 and "--quick" in missing.output


UNSERVED_DEVICES = [
    "tpu",
    "meta",
    *(["cuda"] if not torch.cuda.is_available() else []),
    *(["cuda:7"] if torch.cuda.device_count() <= 7 else []),
]
"""--device values this machine cannot serve: unknown names, other device types, CUDA it lacks."""


@pytest.fixture(scope="module")
def untrained_checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A checkpoint that loads: a device problem is then the only thing wrong with an eval."""
    from lanrocli.agent.settings import BufferSettings, SACSettings
    from lanrocli.train.trainer import Trainer, TrainSettings

    trainer = Trainer(
        TrainSettings(task="reach", buffer=BufferSettings(size=10)), SACSettings(hidden_size=16, obs_size=16)
    )
    return trainer.save(tmp_path_factory.mktemp("run") / "checkpoint", resumable=False)


@pytest.mark.parametrize("device", UNSERVED_DEVICES)
def test_eval_on_a_device_this_machine_cannot_serve_is_a_clear_error(untrained_checkpoint: Path, device: str) -> None:
    result = runner.invoke(app, ["eval", str(untrained_checkpoint), "--episodes", "1", "--device", device])
    assert result.exit_code == 2, result.output
    assert "error:" in result.output and device in result.output and "Traceback" not in result.output


@pytest.mark.parametrize("device", UNSERVED_DEVICES)
def test_train_on_a_device_this_machine_cannot_serve_is_a_clear_error(tmp_path: Path, device: str) -> None:
    out = tmp_path / "run"
    result = runner.invoke(app, ["train", "--quick", "--out", str(out), "--device", device])
    assert result.exit_code == 2, result.output
    assert "error:" in result.output and device in result.output and "Traceback" not in result.output
    assert not out.exists(), "the device is checked before the run folder is made"


def test_eval_acting_attention_is_recorded_and_refused_where_nothing_attends(
    untrained_checkpoint: Path, tmp_path: Path
) -> None:
    from lanrocli.agent.settings import BufferSettings, SACSettings
    from lanrocli.train.trainer import Trainer, TrainSettings

    settings = SACSettings(hidden_size=16, obs_size=16, architecture="objects")
    attending = Trainer(TrainSettings(task="reach", buffer=BufferSettings(size=10)), settings).save(
        tmp_path / "checkpoint", resumable=False
    )
    records = {}
    for rule in ("soft", "argmax"):
        result = runner.invoke(app, ["eval", str(attending), "--episodes", "2", "--acting-attention", rule, "--json"])
        assert result.exit_code == 0, result.output
        records[rule] = json.loads(result.output)
    assert records["soft"]["acting_attention"] == "soft" and records["argmax"]["acting_attention"] == "argmax"
    flat = runner.invoke(app, ["eval", str(untrained_checkpoint), "--episodes", "1", "--acting-attention", "argmax"])
    assert flat.exit_code == 2 and "needs architecture 'objects'" in flat.output, flat.output
    scripted = runner.invoke(app, ["eval", "oracle", "--acting-attention", "argmax"])
    assert scripted.exit_code == 2 and "scripted policies" in scripted.output, scripted.output


def test_eval_table_has_every_form_and_marks_what_is_not_judged() -> None:
    result = runner.invoke(
        app, ["eval", "mistaken", "--episodes", "3", "--correction-rate", "1", "--negations", "--kinds", "wrong_object"]
    )
    assert result.exit_code == 0, result.output
    for form in ("after an excuse", "after a negation", "after an edit"):
        assert f"correction spoken, {form}" in result.output
    assert (
        "wrong_object, correction spoken *" in result.output and "* fewer than 30 spoken corrections" in result.output
    )


def test_eval_correction_test_of_a_checkpoint_and_its_refusals(untrained_checkpoint: Path) -> None:
    result = runner.invoke(app, ["eval", str(untrained_checkpoint), "--correction-test", "--episodes", "2", "--json"])
    assert result.exit_code == 0, result.output
    record = json.loads(result.output)
    assert record["episodes_from"]["correction_test"] and record["env"]["correction_rate"] == 1.0
    assert record["episodes"] <= 2 and record["quota"]["episodes"] == 2 and "by_form" in record
    table = runner.invoke(app, ["eval", str(untrained_checkpoint), "--correction-test", "--episodes", "1"])
    assert table.exit_code == 0 and "correction test (" in table.output, table.output
    refused = runner.invoke(app, ["eval", "oracle", "--correction-test"])
    assert refused.exit_code == 2 and "scripted policy" in refused.output
    refused = runner.invoke(app, ["eval", str(untrained_checkpoint), "--correction-test", "--seed", "4"])
    assert refused.exit_code == 2 and "--seed" in refused.output
    refused = runner.invoke(app, ["eval", str(untrained_checkpoint), "--second-corrections", "30"])
    assert refused.exit_code == 2 and "add --correction-test" in refused.output
    # Its stage corrects at most once an episode: a second correction is never spoken there.
    refused = runner.invoke(app, ["eval", str(untrained_checkpoint), "--correction-test", "--second-corrections", "3"])
    assert refused.exit_code == 2 and "never spoken" in refused.output, refused.output


def test_eval_question_test_of_a_shipped_agent_and_its_refusals(untrained_checkpoint: Path) -> None:
    result = runner.invoke(app, ["eval", "push", "--question-test", "--episodes", "8", "--level", "0.9", "--json"])
    assert result.exit_code == 0, result.output
    record = json.loads(result.output)
    assert record["episodes_from"]["question_test"] and record["env"]["questions"] == 1
    assert record["episodes"] == 8 == record["off"]["episodes"] and record["off"]["env"]["questions"] == 0
    assert record["calibration"]["level"] == 0.9 and record["coverage"]["episodes"] == 8
    assert sum(figures["episodes"] for figures in record["questions"].values()) == 8
    table = runner.invoke(app, ["eval", "push", "--question-test", "--episodes", "4"])
    words = " ".join(table.output.split())
    assert table.exit_code == 0 and "question test" in words and "success without a question" in words, words
    corrections = runner.invoke(
        app, ["eval", "push", "--correction-test", "--questions", "1", "--episodes", "4", "--json"]
    )
    assert corrections.exit_code == 0, corrections.output
    record = json.loads(corrections.output)
    assert record["env"]["questions"] == 1 and "calibration" in record and record["questions"]
    refused = runner.invoke(app, ["eval", "push", "--level", "0.9"])
    assert refused.exit_code == 2 and "add --question-test" in refused.output
    refused = runner.invoke(app, ["eval", "oracle", "--question-test"])
    assert refused.exit_code == 2 and "scripted policy asks none" in refused.output
    refused = runner.invoke(app, ["eval", "oracle", "--questions", "1"])
    assert refused.exit_code == 2 and "scripted policies ask none" in refused.output, refused.output
    refused = runner.invoke(app, ["eval", "push", "--question-test", "--level", "0.999"])
    assert refused.exit_code == 2 and "too few" in refused.output, refused.output
    # Its stage corrects at most once an episode: no room for an answer and a correction after it.
    refused = runner.invoke(app, ["eval", str(untrained_checkpoint), "--question-test", "--episodes", "2"])
    assert refused.exit_code == 2 and "raise max_corrections to 2" in refused.output, refused.output
