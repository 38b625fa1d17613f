"""The ``lanro`` command line, driven through typer's CliRunner."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from lanrocli import __version__
from lanrocli.cli import app
from lanrocli.language import grammar_vocabulary

runner = CliRunner()


def test_help_lists_commands() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    assert "sample-instructions" in result.output


def test_version() -> None:
    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0 and __version__ in result.output


def test_sample_json_is_reproducible_and_well_formed() -> None:
    args = ["sample-instructions", "--task", "push", "--n", "25", "--seed", "4", "--corrections", "--negations", "--json"]
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


def test_all_enumerates_every_instruction() -> None:
    result = runner.invoke(app, ["sample-instructions", "--all", "--task", "grasp"])
    lines = result.output.strip().splitlines()
    assert result.exit_code == 0 and len(lines) == len(set(lines)) == 3 * 99


def test_stats_match_hand_counts() -> None:
    result = runner.invoke(
        app, ["sample-instructions", "--all", "--corrections", "--negations", "--rare", "--stats", "--json"]
    )
    stats = json.loads(result.output)
    # 3 verbs x (18 colour words x 9 shape words + 9 shape words + 18 colour words) = 567 instructions;
    # 6 beginnings x (9 x 9 + 9 + 9) = 594 corrections.
    assert stats["sentences"] == stats["distinct_sentences"] == 567 * 594
    assert stats["vocabulary_size"] == 52 and stats["max_length"] == 10
    assert stats["by_form"] == {"colour_shape": 486 * 594, "shape": 27 * 594, "colour": 54 * 594}
    assert stats["by_beginning"] == {"excuse": 567 * 4 * 99, "negation": 567 * 99, "edit": 567 * 99}


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
        [sys.executable, "-c", "from lanrocli.cli import app; app()", "eval", "oracle", "--episodes", "2", "--json"],
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


def test_eval_writes_a_gif(tmp_path) -> None:
    gif = tmp_path / "episodes.gif"
    result = runner.invoke(app, ["eval", "oracle", "--episodes", "1", "--gif", str(gif)])
    assert result.exit_code == 0 and gif.stat().st_size > 1000
