"""A run's TensorBoard events: the train/ group between evaluations, eval/, each stage's test/ figures and the
curriculum as hyperparameters, in the events file of a real run and by the rule that places the points."""

from __future__ import annotations

from typing import Any

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.plugins.hparams import plugin_data_pb2

from lanrocli.config.curriculum import load_curriculum
from lanrocli.train.tensorboard import EVALUATION_FIGURES, TRAIN_POINTS, TensorBoard
from tests.train.runs import Baseline, rows


class Recorder:
    """A writer that keeps the scalars it is given."""

    def __init__(self) -> None:
        self.scalars: dict[str, dict[int, float]] = {}

    def add_scalar(self, tag: str, value: float, step: int) -> None:
        self.scalars.setdefault(tag, {})[step] = value

    def flush(self) -> None: ...


def test_train_points_fall_where_the_steps_pass_each_interval_and_the_clock_skips_evaluations() -> None:
    recorder = Recorder()
    board = TensorBoard(recorder, train_every=10, env_steps=4)
    for steps in range(6, 34, 3):  # three environments: steps 6, 9, 12, ..., 33
        board.train(steps, {"critic_loss": steps / 100, "alpha_loss": None})
    assert sorted(recorder.scalars["train/critic_loss"]) == [12, 21, 30]
    assert "train/alpha_loss" not in recorder.scalars  # nothing to write before the first update
    assert all(rate > 0 for rate in recorder.scalars["train/env_steps_per_second"].values())
    board.mark(33)
    board.train(39, {"critic_loss": 1.0})
    board.train(42, {"critic_loss": 1.0})
    assert sorted(recorder.scalars["train/critic_loss"]) == [12, 21, 30, 42]

    board.evaluation({"env_steps": 40, "success": 0.5, "corrected_success": "", "critic_loss": 2.0, "stage": 1})
    assert recorder.scalars["eval/success"] == {40: 0.5}
    assert {"eval/corrected_success", "eval/critic_loss", "eval/stage"}.isdisjoint(recorder.scalars)
    board.test(80, {"last": {"success": 1.0, "episodes": 4}, "language/blank": {"success": 0.25}})
    assert recorder.scalars["test/last/success"] == {80: 1.0}
    assert recorder.scalars["test/language/blank/success"] == {80: 0.25}


def hyperparameters(accumulator: EventAccumulator) -> dict[str, Any]:
    """The values the HParams dashboard shows for the run."""
    content = accumulator.PluginTagToContent("hparams")["_hparams_/session_start_info"]
    start = plugin_data_pb2.HParamsPluginData.FromString(content).session_start_info
    return {key: getattr(value, value.WhichOneof("kind")) for key, value in start.hparams.items()}


def test_a_run_writes_every_group_and_its_curriculum(straight: Baseline) -> None:
    (events,) = straight.out.glob("events.out.tfevents.*")
    accumulator = EventAccumulator(str(events))
    accumulator.Reload()
    tags = set(accumulator.Tags()["scalars"])
    plan = load_curriculum(straight.curriculum)
    every = plan.eval.every // TRAIN_POINTS
    steps = [event.step for event in accumulator.Scalars("train/env_steps_per_second")]
    assert steps == list(range(every, plan.total_steps + 1, every))
    assert {"train/critic_loss", "train/alpha", "train/entropy", "train/q_mean", "train/train_success"} <= tags
    evaluated = [event.step for event in accumulator.Scalars("eval/success")]
    assert evaluated == [int(row["env_steps"]) for row in rows(straight.out)]
    assert (
        {"success", "corrected_episodes"}
        <= {tag[5:] for tag in tags if tag.startswith("eval/")}
        <= set(EVALUATION_FIGURES)
    )
    ends = [80, 160, 240]
    assert [event.step for event in accumulator.Scalars("test/last/success")] == ends
    assert [event.step for event in accumulator.Scalars("test/language/other/success")] == ends[-1:]
    assert {"test/correction_test/best/corrected_episodes", "test/correction_test/last/success"} <= tags
    values = hyperparameters(accumulator)
    assert values["task"] == "reach" and values["stages[2].env.objects"] == 3 and values["eval.every"] == 40
    assert values["stages[0].env.kinds"] == "null"  # the default, which TensorBoard shows as text
