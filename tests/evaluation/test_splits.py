"""A split's drop is taken from its control where the split has one, from the ordinary test otherwise."""

from __future__ import annotations

from typing import Any

from lanrocli.core.choices import CorrectionForm, Kind, Split
from lanrocli.evaluation.metrics import EpisodeResult
from lanrocli.evaluation.splits import (
    CONTROL,
    CONTROLLED,
    DROP,
    SPLIT_FIGURES,
    control_lines,
    drop,
    in_distribution,
    paired_drops,
    split_lines,
)


def record(corrected: float, spoken: int = 100, success: float = 0.9) -> dict[str, Any]:
    return {
        "episodes": 500,
        "success": success,
        "success_ci": [success - 0.03, success + 0.03],
        "corrected": {"episodes": spoken, "success": corrected, "ci": [corrected - 0.05, corrected + 0.05]},
        "by_kind": {},
    }


LATE = next(f for f in SPLIT_FIGURES if f.split is Split.LATE_CORRECTIONS)
PAIRS = next(f for f in SPLIT_FIGURES if f.split is Split.PAIRS and f.name == "corrected")


def test_only_splits_that_change_the_correction_alone_have_a_control() -> None:
    assert {Split.CORRECTION_WORDS, Split.LATE_CORRECTIONS, Split.PARAPHRASE} == CONTROLLED


def test_the_drop_of_a_controlled_split_is_taken_from_its_control() -> None:
    test = record(0.98)
    late = {**record(0.85), CONTROL: record(0.88)}
    rate, source = in_distribution(LATE, late, test)
    assert source == "control" and rate is not None and rate["success"] == 0.88
    assert round(drop(LATE.read(late), rate) or 0, 6) == 3.0


def test_a_split_without_a_control_is_set_against_the_test() -> None:
    test = record(0.98)
    rate, source = in_distribution(PAIRS, record(0.85), test)
    assert source == "test" and rate is not None and rate["success"] == 0.98
    # A run tested before controls existed: its late corrections fall back to the test, and say so.
    assert in_distribution(LATE, record(0.85), test)[1] == "test"
    assert in_distribution(LATE, record(0.85), None) == (None, "test")


def test_the_report_names_what_each_drop_is_taken_from() -> None:
    splits = {
        "pairs": {"last": record(0.80)},
        "late_corrections": {"last": {**record(0.85), CONTROL: record(0.90)}},
    }
    lines = split_lines(splits, {"last": record(0.98)})
    late = next(line for line in lines if line.startswith("| late_corrections | last |"))
    pairs = next(line for line in lines if line.startswith("| pairs | last | corrected |"))
    assert "| control | +5.0 |" in late and "90.0%" in late
    assert "| test | +18.0 |" in pairs and "98.0%" in pairs


def test_lanro_eval_split_says_the_drop_from_the_control() -> None:
    [line] = control_lines(Split.LATE_CORRECTIONS, {**record(0.85), CONTROL: record(0.90)})
    assert "85.0%" in line and "90.0%" in line and "drop +5.0 points" in line
    assert control_lines(Split.PAIRS, record(0.8)) == []


def results(outcomes: list[bool | None]) -> list[EpisodeResult]:
    """Episodes by outcome where a correction was spoken, None where none was."""
    form = CorrectionForm.EXCUSE
    return [EpisodeResult(bool(won), 50, Kind.AMBIGUITY, None if won is None else form, -10.0) for won in outcomes]


def test_a_paired_drop_counts_each_way_on_its_own_corrected_episodes() -> None:
    control = results([True] * 90 + [False] * 10 + [None] * 100)
    held = results([True] * 80 + [False] * 10 + [None] * 110)  # ten episodes lost, and ten never corrected
    [late] = paired_drops(Split.LATE_CORRECTIONS, held, control).items()
    name, paired = late
    assert name == "corrected" and round(paired["points"], 6) == round(100 * (0.9 - 80 / 90), 6)
    low, high = paired["ci"]
    assert low < paired["points"] < high
    nothing = paired_drops(Split.LATE_CORRECTIONS, results([None] * 200), control)
    assert nothing == {"corrected": None}


def test_the_report_gives_a_paired_interval_where_there_is_one() -> None:
    late = {**record(0.85), CONTROL: record(0.90), DROP: {"corrected": {"points": 5.0, "ci": [1.25, 8.5]}}}
    lines = split_lines({"late_corrections": {"last": late}}, {"last": record(0.98)})
    assert any("| control | +5.0 [+1.2, +8.5] |" in line for line in lines)
