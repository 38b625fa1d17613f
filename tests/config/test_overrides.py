"""``KEY=VALUE`` settings as every command reads them: key paths, YAML values, and every problem of a changed
curriculum located at the setting that caused it."""

from __future__ import annotations

from pathlib import Path

import pytest

from lanrocli.config.curriculum import Curriculum, CurriculumError, load_curriculum
from lanrocli.config.overrides import SettingError, apply_settings, flatten, parse_key, put, read_settings
from tests.train.runs import tiny


def test_key_paths() -> None:
    assert parse_key("stages[0].budget.steps") == ("stages", 0, "budget", "steps")
    assert parse_key("agent.critics") == ("agent", "critics")
    with pytest.raises(SettingError, match="not a key path"):
        parse_key("agent..critics")
    assert flatten({"a": {"b": 1}, "s": [{"c": 2}]}) == {"a.b": 1, "s[0].c": 2}


def test_values_are_read_as_yaml_and_malformed_settings_are_refused() -> None:
    assert read_settings("--set", ["agent.critics=2", "env.kinds=[ambiguity]", "a.b=true", "c=x"]) == {
        "agent.critics": 2,
        "env.kinds": ["ambiguity"],
        "a.b": True,
        "c": "x",
    }
    assert read_settings("--set", ["seed=3"]) == {"seed": 3}  # where the command has no seed option of its own
    for texts, message in [
        (["critics"], "--set critics: expected KEY=VALUE, e.g. --set agent.critics=2"),
        (["=2"], "expected KEY=VALUE"),
        (["a.b=1", "a.b=2"], "--set a.b is given twice"),
        (["a.b=[1"], "--set a.b=[1: '[1' is not a YAML value"),
    ]:
        with pytest.raises(SettingError, match=message.replace("[", r"\[")):
            read_settings("--set", texts)
    with pytest.raises(SettingError, match="give seeds with --seeds"):
        read_settings("--set", ["seed=3"], "--seeds")


def test_a_setting_is_put_where_its_key_path_leads() -> None:
    data = {"agent": {}, "stages": [{"budget": {"steps": 5}}]}
    put(data, ("stages", 0, "budget", "steps"), 9)
    put(data, ("agent", "critics"), 2)
    assert data == {"agent": {"critics": 2}, "stages": [{"budget": {"steps": 9}}]}
    with pytest.raises(SettingError, match=r"stages\[3\]: stages has 1 items, \[0\] to \[0\]"):
        put(data, ("stages", 3, "name"), "x")
    with pytest.raises(SettingError, match="agent.critics is 2, which has no 'x'"):
        put(data, ("agent", "critics", "x"), 1)


def test_every_problem_of_a_changed_curriculum_is_located_at_its_setting(tmp_path: Path) -> None:
    path = tiny(tmp_path)
    base = load_curriculum(path)
    changed = base.with_settings({"agent.critics": 1, "stages[1].budget.steps": 77}, str(path))
    assert (changed.agent.critics, changed.stages[1].budget.steps) == (1, 77)
    assert changed.model_copy(update={"agent": base.agent, "stages": base.stages}) == base
    settings = [("--set", "agent.critcs", 2), ("--set", "stages[7].env.objects", 2), ("--set", "eval.every", -1)]
    with pytest.raises(CurriculumError) as caught:
        apply_settings(Curriculum, base.model_dump(mode="json"), settings, str(path))
    assert [str(problem) for problem in caught.value.problems] == [
        "--set stages[7].env.objects=2: stages[7]: stages has 3 items, [0] to [2]",
        "--set agent.critcs=2: agent.critcs: unknown key 'critcs'; did you mean 'critics'?",
        "--set eval.every=-1: eval.every: Input should be greater than 0, got -1",
    ]
