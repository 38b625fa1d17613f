"""Reading curriculum files: input bounded before it is expanded, repeated keys, every problem located."""

from __future__ import annotations

import resource
import subprocess
import sys
from pathlib import Path

import pytest

from lanrocli.config.yamlfile import MAX_BYTES, MAX_DEPTH, MAX_VALUES, CurriculumError, Problem, parse, read

ALIAS_BOMB = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"{name}: &{name} [{', '.join([f'*{previous}'] * 9)}]\n" for previous, name in zip("abcdefgh", "bcdefghi")
)
"""A few hundred bytes that expand to 9**9 strings: unbounded, reading it ran for minutes at gigabytes."""

MINIMAL = "name: demo\ntask: push\nstages:\n  - name: first\n    budget: {steps: 1000}\n"

MEMORY = 1 << 30
"""Address space for a ``lanro check`` subprocess: ample for the command, far too little for an expanded bomb."""


def only_problem(text: str) -> Problem:
    with pytest.raises(CurriculumError) as caught:
        parse(text, "c.yaml")
    assert len(caught.value.problems) == 1, caught.value.problems
    return caught.value.problems[0]


def lanro_check(path: Path) -> subprocess.CompletedProcess[str]:
    """``lanro check path`` in a fresh interpreter of bounded memory; a bomb that got through would make it
    fail for memory or run into the timeout instead of exiting 2."""

    def bound_memory() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))

    command = [sys.executable, "-c", "from lanrocli.cli.app import app; app(prog_name='lanro')", "check", str(path)]
    return subprocess.run(command, capture_output=True, text=True, timeout=60, preexec_fn=bound_memory)


def test_alias_bomb_is_refused_at_its_line() -> None:
    problem = only_problem(ALIAS_BOMB)
    assert problem.file == "c.yaml" and problem.line is not None and 2 <= problem.line <= 9
    assert f"more than {MAX_VALUES:,} values" in problem.message and "alias" in problem.message


def test_aliases_that_expand_to_little_are_read() -> None:
    data, _ = parse(MINIMAL + "agent: &agent {critics: 2}\nother: *agent\nlist: [*agent, *agent]\n", "c.yaml")
    assert data["other"] == data["agent"] == {"critics": 2} and data["list"] == [{"critics": 2}] * 2


def test_an_alias_inside_its_own_value_is_refused() -> None:
    problem = only_problem("a: &a [1, *a]\n")
    assert problem.line == 1 and "*a" in problem.message and "endless" in problem.message


def test_too_many_values_without_aliases_are_refused() -> None:
    problem = only_problem("a: [" + "1, " * MAX_VALUES + "1]\n")
    assert problem.line == 1 and f"more than {MAX_VALUES:,} values" in problem.message


def test_nesting_beyond_the_limit_is_refused() -> None:
    depth = MAX_DEPTH + 1
    problem = only_problem("a: " + "[" * depth + "]" * depth + "\n")
    assert problem.line == 1 and f"more than {MAX_DEPTH} deep" in problem.message
    deep = "a: " + "[" * 5000 + "]" * 5000 + "\n"  # far beyond Python's recursion limit
    assert "deep" in only_problem(deep).message


def test_a_file_over_the_size_limit_is_refused_before_it_is_parsed(tmp_path: Path) -> None:
    path = tmp_path / "big.yaml"
    path.write_text("name: big\n" + "# " + "x" * (MAX_BYTES - 12) + "\n")
    with pytest.raises(CurriculumError) as caught:
        read(path)
    [problem] = caught.value.problems
    assert problem.file == path and f"larger than {MAX_BYTES:,} bytes" in problem.message


def test_the_size_limit_holds_for_each_file_of_an_extends_chain(tmp_path: Path) -> None:
    parent = tmp_path / "parent.yaml"
    parent.write_text(MINIMAL + "# " + "x" * MAX_BYTES + "\n")
    child = tmp_path / "child.yaml"
    child.write_text("extends: parent.yaml\nseed: 3\n")
    with pytest.raises(CurriculumError) as caught:
        read(child)
    [problem] = caught.value.problems
    assert problem.file == parent and "larger than" in problem.message


def test_a_key_set_twice_is_an_error_naming_both_lines() -> None:
    problem = only_problem("name: demo\nseed: 1\ntask: push\nstages: []\nseed: 2\n")
    assert (problem.file, problem.line, problem.path) == ("c.yaml", 5, "seed")
    assert "line 2" in problem.message


def test_a_key_set_twice_deep_inside_is_an_error_with_its_path() -> None:
    text = MINIMAL + "    env:\n      objects: 2\n      mode: colour\n      objects: 3\n"
    problem = only_problem(text)
    assert (problem.line, problem.path) == (9, "stages[0].env.objects") and "line 7" in problem.message
    flow = only_problem(MINIMAL + "agent: {critics: 1, critics: 2}\n")
    assert (flow.line, flow.path) == (6, "agent.critics")


def test_every_repeated_key_is_reported_at_once() -> None:
    with pytest.raises(CurriculumError) as caught:
        parse("a: 1\nb: {x: 1, x: 2}\na: 3\n", "c.yaml")
    assert {(problem.line, problem.path) for problem in caught.value.problems} == {(2, "b.x"), (3, "a")}


def test_the_same_key_in_different_mappings_is_no_repetition() -> None:
    data, _ = parse(MINIMAL + "  - name: second\n    budget: {steps: 1000}\n", "c.yaml")
    assert [stage["name"] for stage in data["stages"]] == ["first", "second"]


def test_a_scalar_that_looks_like_a_date_but_is_none_is_located() -> None:
    problem = only_problem("name: demo\nseed: 2024-13-45\n")
    assert problem.line == 2 and "2024-13-45" in problem.message and "quote it" in problem.message


def test_text_that_is_not_utf8_is_located(tmp_path: Path) -> None:
    path = tmp_path / "latin1.yaml"
    path.write_bytes("name: demo\ntask: pousser à\n".encode("latin-1"))
    with pytest.raises(CurriculumError) as caught:
        read(path)
    [problem] = caught.value.problems
    assert (problem.file, problem.line) == (path, 2) and "UTF-8" in problem.message


def test_a_document_that_is_not_a_mapping_is_refused() -> None:
    assert "must be a mapping" in only_problem("- a\n- b\n").message
    assert "found nothing" in only_problem("# only a comment\n").message


BAD_FILES = {
    "alias-bomb": (ALIAS_BOMB, ":5: more than"),
    "ten-megabytes": ("name: big\n" + "# padding, as a curriculum would never have\n" * 240_000, ": larger than"),
    "repeated-key": (
        "name: demo\nseed: 1\ntask: push\nstages: []\nseed: 2\n",
        ":5: seed: set again here, after line 2",
    ),
    "repeated-nested-key": (
        MINIMAL + "    env: {objects: 2,\n          objects: 3}\n",
        ":7: stages[0].env.objects: set again here, after line 6",
    ),
}


@pytest.mark.parametrize("name", BAD_FILES)
def test_lanro_check_refuses_a_bad_file_with_exit_2_and_its_place(tmp_path: Path, name: str) -> None:
    text, expected = BAD_FILES[name]
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    result = lanro_check(path)
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr and f"{path}{expected}" in result.stderr
