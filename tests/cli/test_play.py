"""``lanro play``: a person's lines, piped into the command, drive an agent; the sentence they make is what
the agent reads and what success is judged on."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from lanrocli.cli.app import app
from lanrocli.cli.play_session import PlayError, check_display
from lanrocli.envs.caption import BAND
from lanrocli.language import ObjectProps, grammar_vocabulary
from lanrocli.language.typed import Grammar, Utterance, unknown_words, words_of

runner = CliRunner()

RED, BLUE, GREEN = ObjectProps("red", "cube"), ObjectProps("blue", "cube"), ObjectProps("green", "cylinder")


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An untrained push agent: enough to play the mechanics of an episode (two objects, colour mode)."""
    from lanrocli.agent.settings import BufferSettings, SACSettings
    from lanrocli.train.trainer import Trainer, TrainSettings

    trainer = Trainer(
        TrainSettings(task="push", buffer=BufferSettings(size=10)), SACSettings(hidden_size=16, obs_size=16)
    )
    return trainer.save(tmp_path_factory.mktemp("run") / "checkpoint", resumable=False)


@pytest.fixture(scope="module")
def red_and_blue_seed() -> int:
    """A seed whose scene (the checkpoint's stage: two cubes) holds a red and a blue cube."""
    from lanrocli.envs.env import LanroEnv

    env = LanroEnv("push")
    try:
        for seed in range(1000):
            if set(env.reset(seed=seed)[1]["objects"]) == {RED, BLUE}:
                return seed
    finally:
        env.close()
    raise AssertionError("no scene with a red and a blue cube among the first 1000 seeds")


def play(checkpoint: Path, lines: str, *options: str):  # type: ignore[no-untyped-def]
    return runner.invoke(app, ["play", str(checkpoint), "--device", "cpu", *options], input=lines)


def test_instruction_and_correction_play_an_episode_that_changes_goal_and_writes_a_gif(
    checkpoint: Path, red_and_blue_seed: int, tmp_path: Path
) -> None:
    out = tmp_path / "gifs"
    result = play(
        checkpoint,
        "push the red cube\n\nsorry the blue cube\n",
        "--seed",
        str(red_and_blue_seed),
        "--steps-per-line",
        "2",
        "--max-episode-steps",
        "6",
        "--gif",
        str(out),
    )
    assert result.exit_code == 0, result.output
    output = result.output
    assert "on the table: " in output and "red cube" in output and "blue cube" in output
    assert output.index("goal: the red cube") < output.index("goal: the blue cube")
    assert "correction at step 4: the agent now reads 'push the red cube sorry the blue cube'" in output
    assert "step   4  'push the red cube'" in output and "step   5  'push the red cube sorry the blue cube'" in output
    assert "episode 1: no success in 6 steps" in output and "1 episode, 0 successes" in output
    assert "warning" not in output, "an in-grammar sentence of known words is neither flagged nor named"
    with Image.open(out / "episode-1.gif") as gif:
        assert gif.n_frames == 7, "the first frame and one per step"
        captions = []
        for frame in range(gif.n_frames):
            gif.seek(frame)
            captions.append(np.asarray(gif.convert("RGB"))[:BAND].astype(int))

    def changed(a: int, b: int) -> int:
        """Caption pixels that differ between two frames by more than the GIF's palette may shift them."""
        return int((np.abs(captions[a] - captions[b]).max(axis=2) > 60).sum())

    assert changed(0, 4) == 0, "the caption stays until the correction is spoken"
    assert changed(4, 5) > 50 and changed(5, 6) == 0, "then it shows the correction"


def test_unknown_word_is_named_as_unk_and_an_ambiguous_sentence_is_said_to_single_out_nothing(
    checkpoint: Path, red_and_blue_seed: int
) -> None:
    result = play(checkpoint, "push the azureish cube\n", "--seed", str(red_and_blue_seed), "--max-episode-steps", "3")
    assert result.exit_code == 0, result.output
    assert "unknown word 'azureish' read as <unk>" in result.output
    assert "unknown word 'push'" not in result.output and "unknown word 'cube'" not in result.output
    assert "singles out no object" in result.output
    assert "red cube" in result.output.split("singles out no object")[1]
    assert "(the step limit; the sentence singled out no object)" in result.output


def test_sentence_outside_the_grammar_is_flagged_and_played(checkpoint: Path, red_and_blue_seed: int) -> None:
    result = play(checkpoint, "touch the red cube\n", "--seed", str(red_and_blue_seed), "--max-episode-steps", "3")
    assert result.exit_code == 0, result.output
    assert "'touch the red cube' is outside the grammar of push" in result.output
    assert "goal: the red cube" in result.output and "episode 1: no success in 3 steps" in result.output


def test_episodes_follow_until_the_input_ends_and_left_over_empty_lines_are_skipped(checkpoint: Path) -> None:
    result = play(
        checkpoint, "push the cube\n\n\n\n\nmove the cube\n\n", "--max-episode-steps", "2", "--steps-per-line", "5"
    )
    assert result.exit_code == 0, result.output
    assert "episode 2: no success in 2 steps" in result.output and "2 episodes, 0 successes" in result.output
    assert "episode 3" not in result.output, "no scene is drawn once the input has ended"


def test_episodes_option_stops_play(checkpoint: Path) -> None:
    result = play(checkpoint, "push the cube\npush the cube\n", "--max-episode-steps", "1", "--episodes", "1")
    assert result.exit_code == 0 and "1 episode, 0 successes" in result.output and "episode 2" not in result.output


def test_correction_too_long_to_read_is_not_given(checkpoint: Path) -> None:
    result = play(
        checkpoint,
        "push the cube\nno i meant the red cube after all\n",
        "--max-episode-steps",
        "2",
        "--steps-per-line",
        "1",
    )
    assert result.exit_code == 0, result.output
    assert "correction not given" in result.output and "correction at step" not in result.output


@pytest.mark.parametrize(
    ("lines", "message"),
    [
        ("\npush the red cube\n", "type an instruction such as 'push the "),
        ("", "the input ended before any instruction"),
        ("push the red cube over there next to the other cube\n", "has 11 words"),
    ],
)
def test_unreadable_first_instruction_is_a_clear_error(checkpoint: Path, lines: str, message: str) -> None:
    result = play(checkpoint, lines)
    assert result.exit_code == 2, result.output
    assert "error:" in result.output and message in result.output
    assert "Traceback" not in result.output and "step " not in result.output


@pytest.mark.parametrize("kind", ["empty folder", "text file", "missing"])
def test_a_path_that_is_not_a_checkpoint_exits_2_with_a_clear_message(tmp_path: Path, kind: str) -> None:
    path = tmp_path / "notes.txt"
    if kind == "empty folder":
        path.mkdir()
    elif kind == "text file":
        path.write_text("this is no checkpoint\n")
    result = play(path, "push the red cube\n")
    assert result.exit_code == 2, result.output
    assert f"cannot load a trained agent from {path}" in result.output
    assert "Traceback" not in result.output and "episode" not in result.output


def test_gif_that_is_a_file_and_task_with_other_actions_are_clear_errors(checkpoint: Path, tmp_path: Path) -> None:
    file = tmp_path / "out.gif"
    file.write_bytes(b"")
    result = play(checkpoint, "push the red cube\n", "--gif", str(file))
    assert result.exit_code == 2 and "is a file; give a folder" in result.output
    result = play(checkpoint, "grasp the red cube\n", "--task", "grasp")
    assert result.exit_code == 2 and "was trained on push (3 actions); grasp needs 4" in result.output


def test_gui_needs_a_display() -> None:
    with pytest.raises(PlayError, match="no display"):
        check_display({}, "linux")
    check_display({"DISPLAY": ":0"}, "linux")
    check_display({}, "darwin")


def test_words_are_read_as_the_grammar_writes_them() -> None:
    assert words_of("  Sorry, the BLUE cube!\n") == ("sorry", "the", "blue", "cube")
    assert unknown_words(words_of("push the azureish cube, azureish!"), grammar_vocabulary()) == ["azureish"]


def test_grammar_knows_the_tasks_sentences() -> None:
    push = Grammar.of("push")
    assert Utterance(words_of("push the red cube")) in push
    assert Utterance(words_of("shift the azure brick"), words_of("not the red cube")) in push
    assert Utterance(words_of("reach the red cube")) not in push
    assert Utterance(words_of("push the red cube"), words_of("sorry the azure cube")) not in push, (
        "corrections use common words"
    )
    assert Utterance(words_of("push red cube")) not in push


def fitting(
    instruction: str, correction: str | None = None, objects: tuple[ObjectProps, ...] = (RED, BLUE, GREEN)
) -> list[ObjectProps]:
    said = Utterance(words_of(instruction), words_of(correction) if correction else None)
    return [objects[i] for i in said.fitting(objects)]


def test_a_sentence_singles_out_objects_as_the_instructor_means_them() -> None:
    assert fitting("push the red block") == [RED]
    assert fitting("push the scarlet object") == [RED], "rare words name their colour"
    assert fitting("push the cube") == [RED, BLUE]
    assert fitting("push the cube", "sorry the blue object") == [BLUE], "a correction narrows an ambiguity"
    assert fitting("push the cube", "not the red cube") == [BLUE]
    assert fitting("push the red cube", "actually the green barrel") == [GREEN], "an instruction correction retracts"
    assert fitting("push the red cube", "not the red cube") == [BLUE, GREEN]
    assert fitting("push the green cube") == [], "no green cube on the table"
    assert fitting("push the red blue cube") == []
    assert fitting("push it") == [RED, BLUE, GREEN]


def test_a_chain_of_corrections_narrows_what_is_left_each_time() -> None:
    said = Utterance(words_of("push the cube object"))
    said = said.corrected(words_of("not the red cube")).corrected(words_of("not the blue cube"))
    assert said.text == "push the cube object not the red cube not the blue cube" and said.length == 12
    yellow = ObjectProps("yellow", "cube")
    assert said.fitting((RED, BLUE, yellow)) == [2]
    assert Utterance(words_of("push the cube object"), words_of("not the red cube")).fitting((RED, BLUE, yellow)) == [
        1,
        2,
    ]
    assert said in Grammar.of("push")


def test_the_agent_asks_which_one_and_reads_the_typed_answer() -> None:
    """The shipped push agent, asked to push "the cube" beside two cubes, asks which one; the answer typed on
    standard input is appended to the sentence as the instructor's would be, and success is judged on it.
    A sentence that singles out one object is acted on without a question."""
    result = play(
        Path("push"), "push the cube object\nthe blue cube\n\n\n\n\n\n\n\n\n", "--questions", "1", "--seed", "3"
    )
    assert result.exit_code == 0, result.output
    assert "on the table: green cuboid, blue cube, cyan cube" in result.output
    assert "the agent asks: which one: the blue cube or the cyan cube?" in result.output
    assert "the agent now reads 'push the cube object the blue cube'" in result.output
    assert "goal: the blue cube" in result.output and "success" in result.output.splitlines()[-2]
    clear = play(Path("push"), "push the cyan cube\n\n\n\n\n\n\n\n\n", "--questions", "1", "--seed", "3")
    assert clear.exit_code == 0, clear.output
    assert "asks" not in clear.output and "goal: the cyan cube" in clear.output


def test_questions_without_room_for_an_answer_or_a_rule_are_clear_errors(checkpoint: Path) -> None:
    result = play(checkpoint, "push the red cube\n", "--questions", "2")
    assert result.exit_code == 2
    assert "raise max_corrections to 2" in result.output
    # One question fits its plain stage, but the rule is calibrated on correction episodes, which need two places.
    result = play(checkpoint, "push the red cube\n", "--questions", "1")
    assert result.exit_code == 2 and "cannot be calibrated" in result.output, result.output
