"""Curriculum files: defaults, located error messages (path and line), extends, and the derived plans."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest

from lanrocli.agent.settings import BufferSettings, SACSettings
from lanrocli.config.curriculum import (
    QUICK_TEST_EPISODES,
    Curriculum,
    CurriculumError,
    Problem,
    builtin_curriculum,
    diff_curricula,
    find_curriculum,
    load_curriculum,
    packaged_curricula,
)
from lanrocli.config.sections import STAGE_BUFFER_KEYS, EnvConfig
from lanrocli.core.choices import Kind, Mode, Split
from lanrocli.envs.settings import EnvSettings
from lanrocli.language import COLOURS, TASKS, ObjectProps
from lanrocli.tasks import Task

MINIMAL = """\
name: demo
task: push
stages:
  - name: first
    budget: {steps: 1000}
"""


def write(directory: Path, name: str, text: str) -> Path:
    path = directory / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def problems_of(path: Path) -> list[Problem]:
    with pytest.raises(CurriculumError) as caught:
        load_curriculum(path)
    return caught.value.problems


def only_problem(path: Path) -> Problem:
    problems = problems_of(path)
    assert len(problems) == 1, problems
    return problems[0]


def test_valid_file_loads_with_defaults(tmp_path: Path) -> None:
    curriculum = load_curriculum(write(tmp_path, "c.yaml", MINIMAL))
    assert (curriculum.name, curriculum.task, curriculum.seed, curriculum.envs) == ("demo", "push", 0, 2)
    assert curriculum.learning_starts == 1000
    assert (curriculum.eval.every, curriculum.eval.episodes, curriculum.test.episodes) == (10_000, 100, 500)
    assert curriculum.agent.settings() == SACSettings()
    stage = curriculum.stages[0]
    assert stage.env == EnvConfig()
    assert (stage.env.objects, stage.env.mode, stage.env.correction_rate, stage.env.kinds) == (2, "colour", 0.0, None)
    assert (stage.budget.steps, stage.promote, stage.on_budget) == (1000, None, "advance")
    assert (curriculum.max_objects, curriculum.total_steps) == (2, 1000)


def test_env_section_is_the_environments_settings() -> None:
    settings = EnvConfig(objects=3, correction_rate=0.5, kinds=["ambiguity"]).settings()
    assert settings == EnvSettings(objects=3, correction_rate=0.5, kinds=(Kind.AMBIGUITY,))
    assert settings.to_dict() == {
        "objects": 3,
        "mode": "colour",
        "correction_rate": 0.5,
        "negations": False,
        "negation_rate": None,
        "max_delay": 0,
        "max_corrections": 1,
        "rare_words": False,
        "kinds": ["ambiguity"],
        "max_episode_steps": None,
        "random_start": 0.0,
        "object_start": 0.0,
        "mistake_start": 0.0,
        "questions": 0,
        "question_penalty": 0.0,
        "question_steps": 1,
    }
    assert list(EnvConfig.model_fields) == [f.name for f in dataclasses.fields(EnvSettings)]


def test_choices_are_the_shared_enums() -> None:
    assert Curriculum.model_fields["task"].annotation is Task
    assert EnvConfig.model_fields["mode"].annotation is Mode
    assert set(TASKS) == {task.value for task in Task}


def test_unknown_key_suggests_the_closest_field(tmp_path: Path) -> None:
    text = MINIMAL.replace("    budget:", "    env:\n      corection_rate: 0.5\n    budget:")
    problem = only_problem(write(tmp_path, "c.yaml", text))
    assert (problem.line, problem.path) == (6, "stages[0].env.corection_rate")
    assert problem.message == "unknown key 'corection_rate'; did you mean 'correction_rate'?"


def test_unknown_key_without_a_close_field_has_no_suggestion(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", MINIMAL + "zzzz: 1\n"))
    assert (problem.line, problem.path, problem.message) == (6, "zzzz", "unknown key 'zzzz'")


def test_wrong_type_is_located(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", MINIMAL.replace("task: push", "task: push\nseed: many")))
    assert (problem.line, problem.path) == (3, "seed")
    assert "integer" in problem.message and "'many'" in problem.message


def test_out_of_range_value_in_second_stage(tmp_path: Path) -> None:
    text = MINIMAL + "  - name: second\n    env:\n      correction_rate: 1.5\n    budget: {steps: 10}\n"
    path = write(tmp_path, "c.yaml", text)
    problem = only_problem(path)
    assert (problem.file, problem.line, problem.path) == (path, 8, "stages[1].env.correction_rate")
    assert "within [0, 1], got 1.5" in problem.message
    assert str(problem) == f"{path}:8: stages[1].env.correction_rate: {problem.message}"


def test_random_start_is_a_share_of_episodes(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", MINIMAL + "    env: {random_start: 2}\n"))
    assert (problem.line, problem.path) == (6, "stages[0].env.random_start")
    assert "within [0, 1], got 2" in problem.message
    stage = load_curriculum(write(tmp_path, "ok.yaml", MINIMAL + "    env: {random_start: 0.5}\n")).stages[0]
    assert stage.env.settings().random_start == 0.5


def test_object_starts_need_a_gripper_task(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", MINIMAL + "    env: {object_start: 0.5}\n"))
    assert (problem.line, problem.path) == (3, "stages")
    assert problem.message.startswith("stages[0].env: object_start is 0.5, but it needs a task with a gripper")
    grasp = MINIMAL.replace("task: push", "task: grasp") + "    env: {object_start: 0.5, random_start: 0.5}\n"
    assert load_curriculum(write(tmp_path, "ok.yaml", grasp)).stages[0].env.settings().object_start == 0.5


def test_empty_stage_list(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", "name: demo\ntask: push\nstages: []\n"))
    assert (problem.line, problem.path, problem.message) == (3, "stages", "a curriculum needs at least one stage")


def test_unknown_task_lists_the_allowed_ones(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", MINIMAL.replace("task: push", "task: fly")))
    assert (problem.line, problem.path) == (2, "task")
    assert all(f"'{task}'" in problem.message for task in TASKS)


def test_promote_on_corrected_needs_corrections(tmp_path: Path) -> None:
    text = MINIMAL + "    promote:\n      success: 0.8\n      on: corrected\n"
    problem = only_problem(write(tmp_path, "c.yaml", text))
    assert (problem.line, problem.path) == (6, "stages[0].promote")
    assert "correction_rate > 0" in problem.message


def test_promote_on_corrected_with_corrections_loads(tmp_path: Path) -> None:
    text = MINIMAL + "    env: {correction_rate: 0.5}\n    promote: {success: 0.8, on: corrected, patience: 2}\n"
    promote = load_curriculum(write(tmp_path, "c.yaml", text)).stages[0].promote
    assert promote is not None
    assert (promote.success, promote.on, promote.patience, promote.statistic) == (0.8, "corrected", 2, "mean")


def test_promote_statistic_is_mean_or_lower_bound(tmp_path: Path) -> None:
    text = MINIMAL + "    promote: {success: 0.8, statistic: lower_bound}\n"
    promote = load_curriculum(write(tmp_path, "c.yaml", text)).stages[0].promote
    assert promote is not None and promote.statistic == "lower_bound"
    problem = only_problem(write(tmp_path, "d.yaml", text.replace("lower_bound", "median")))
    assert problem.path == "stages[0].promote.statistic" and "lower_bound" in problem.message


def test_evaluation_correction_share_is_a_probability_above_zero(tmp_path: Path) -> None:
    curriculum = load_curriculum(write(tmp_path, "c.yaml", "eval: {correction_rate: 1}\n" + MINIMAL))
    assert curriculum.eval.correction_rate == 1.0 and "100% of them correction episodes" in curriculum.eval.described()
    assert load_curriculum(write(tmp_path, "d.yaml", MINIMAL)).eval.described() == "100 fresh episodes"
    problem = only_problem(write(tmp_path, "e.yaml", "eval: {correction_rate: 0}\n" + MINIMAL))
    assert (problem.line, problem.path) == (1, "eval.correction_rate") and "greater than 0" in problem.message


def test_a_stage_evaluation_replaces_the_curriculums_keys_it_gives_for_that_stage_alone(tmp_path: Path) -> None:
    text = (
        "eval: {every: 500, episodes: 40}\n"
        + MINIMAL
        + ("  - name: second\n    budget: {steps: 1000}\n    eval: {episodes: 80, correction_rate: 1, every: null}\n")
    )
    curriculum = load_curriculum(write(tmp_path, "c.yaml", text))
    assert curriculum.evaluation(0) == curriculum.eval
    assert (curriculum.evaluation(1).every, curriculum.evaluation(1).episodes) == (500, 80)
    assert curriculum.evaluation(1).correction_rate == 1.0 and curriculum.eval.correction_rate is None
    assert load_curriculum(write(tmp_path, "d.yaml", curriculum.to_yaml())) == curriculum  # config.yaml round trip
    assert curriculum.quick().evaluation(1).episodes == 5
    problem = only_problem(write(tmp_path, "e.yaml", text.replace("correction_rate: 1", "correction_rate: 2")))
    assert (problem.line, problem.path) == (
        9,
        "stages[1].eval.correction_rate",
    ) and "less than or equal" in problem.message


def test_a_stage_buffer_replaces_the_curriculums_sampling_keys_it_gives_for_that_stage_alone(tmp_path: Path) -> None:
    text = (
        "buffer: {relabel_ratio: 0.5, size: 5000}\n"
        + MINIMAL
        + ("  - name: second\n    budget: {steps: 1000}\n    buffer: {fresh_targets: true, relabel_ratio: 0.8}\n")
    )
    curriculum = load_curriculum(write(tmp_path, "c.yaml", text))
    assert curriculum.buffer_settings(0) == curriculum.buffer.settings()
    second = curriculum.buffer_settings(1)
    assert (second.fresh_targets, second.relabel_ratio, second.size) == (True, 0.8, 5000)
    assert load_curriculum(write(tmp_path, "d.yaml", curriculum.to_yaml())) == curriculum  # config.yaml round trip
    problem = only_problem(write(tmp_path, "e.yaml", text.replace("relabel_ratio: 0.8", "relabel_ratio: 2")))
    assert (problem.line, problem.path) == (9, "stages[1].buffer.relabel_ratio") and "[0, 1]" in problem.message
    problem = only_problem(write(tmp_path, "f.yaml", text.replace("fresh_targets: true", "size: 100")))
    assert problem.path == "stages[1].buffer.size"  # the run's buffer is built once: a stage cannot resize it


def test_a_stage_may_change_every_sampling_setting_and_none_that_builds_the_buffer() -> None:
    fields = {f.name for f in dataclasses.fields(BufferSettings)}
    assert set(STAGE_BUFFER_KEYS) == fields - {"size"}


def test_common_ground_needs_rare_words(tmp_path: Path) -> None:
    text = MINIMAL + "    env: {correction_rate: 0.5, kinds: [common_ground]}\n"
    problem = only_problem(write(tmp_path, "c.yaml", text))
    assert (problem.line, problem.path) == (6, "stages[0].env")
    assert "rare_words" in problem.message
    load_curriculum(write(tmp_path, "ok.yaml", text.replace("kinds:", "rare_words: true, kinds:")))


def test_kinds_must_be_distinct_and_not_empty(tmp_path: Path) -> None:
    repeated = only_problem(write(tmp_path, "a.yaml", MINIMAL + "    env: {kinds: [ambiguity, ambiguity]}\n"))
    assert (repeated.line, repeated.path) == (6, "stages[0].env.kinds")
    assert "ambiguity more than once" in repeated.message
    empty = only_problem(write(tmp_path, "b.yaml", MINIMAL + "    env: {kinds: []}\n"))
    assert (empty.path, empty.message.startswith("kinds must name at least one kind")) == ("stages[0].env.kinds", True)


def test_duplicate_stage_names(tmp_path: Path) -> None:
    text = MINIMAL + "  - name: other\n    budget: {steps: 5}\n  - name: first\n    budget: {steps: 5}\n"
    problem = only_problem(write(tmp_path, "c.yaml", text))
    assert (problem.line, problem.path) == (3, "stages")
    assert "stages[0] and stages[2] are both named 'first'" in problem.message


def test_stage_name_must_be_usable_as_a_folder(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", MINIMAL.replace("name: first", "name: ../up")))
    assert (problem.line, problem.path) == (4, "stages[0].name")


def test_bad_agent_setting_reports_the_agents_own_check(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", MINIMAL + "agent: {critics: 3}\n"))
    assert (problem.line, problem.path, problem.message) == (6, "agent", "critics must be 1 or 2, got 3")


def test_unknown_agent_key(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", MINIMAL + "agent:\n  batch_size: 64\n  critic: 2\n"))
    assert (problem.line, problem.path) == (8, "agent.critic")
    assert problem.message == "unknown key 'critic'; did you mean 'critics'?"


def test_missing_keys_are_reported_at_their_parent(tmp_path: Path) -> None:
    path = write(tmp_path, "c.yaml", "name: demo\nstages:\n  - name: first\n")
    problems = {problem.path: problem for problem in problems_of(path)}
    assert set(problems) == {"task", "stages[0].budget"}
    assert problems["task"].line is None and str(problems["task"]) == f"{path}: task: required key is missing"
    assert problems["stages[0].budget"].line == 3


def test_every_problem_is_reported_at_once(tmp_path: Path) -> None:
    text = """\
name: demo
task: fly
seed: -1
agent: {actor_lr: fast}
stages:
  - name: first
    env: {objects: 4, mode: colours}
    budget: {steps: 0}
    on_budget: pause
"""
    path = write(tmp_path, "c.yaml", text)
    with pytest.raises(CurriculumError) as caught:
        load_curriculum(path)
    located = {(problem.line, problem.path) for problem in caught.value.problems}
    assert located == {
        (2, "task"),
        (3, "seed"),
        (4, "agent.actor_lr"),
        (7, "stages[0].env.objects"),
        (7, "stages[0].env.mode"),
        (8, "stages[0].budget.steps"),
        (9, "stages[0].on_budget"),
    }
    lines = str(caught.value).splitlines()
    assert len(lines) == 7 and all(line.startswith(f"{path}:") for line in lines)


def test_yaml_syntax_error_has_its_line(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", "name: demo\ntask: push\nstages: [\n  {name: a\n"))
    assert problem.file == tmp_path / "c.yaml" and problem.line is not None and problem.line >= 4
    assert problem.message.startswith("invalid YAML")


def test_top_level_must_be_a_mapping(tmp_path: Path) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", "- name: a\n"))
    assert "top level must be a mapping" in problem.message


def test_missing_file(tmp_path: Path) -> None:
    problem = only_problem(tmp_path / "absent.yaml")
    assert (problem.file, problem.message) == (tmp_path / "absent.yaml", "no such file")


def test_yaml_on_key_is_a_string_not_a_boolean(tmp_path: Path) -> None:
    text = MINIMAL + "    env: {correction_rate: 0.5}\n    promote:\n      success: 0.5\n      on: corrected\n"
    promote = load_curriculum(write(tmp_path, "c.yaml", text)).stages[0].promote
    assert promote is not None and promote.on == "corrected"


def test_exponent_float_loads_as_float(tmp_path: Path) -> None:
    curriculum = load_curriculum(write(tmp_path, "c.yaml", MINIMAL + "agent: {actor_lr: 1e-3}\n"))
    assert curriculum.agent.actor_lr == 0.001 and isinstance(curriculum.agent.actor_lr, float)
    assert curriculum.agent.settings().actor_lr == 0.001


BASE = """\
name: base
task: push
envs: 4
agent:
  batch_size: 64
  critics: 2
eval: {every: 2000, episodes: 10}
stages:
  - name: a
    budget: {steps: 100}
  - name: b
    budget: {steps: 200}
"""


def test_extends_merges_mappings_and_replaces_lists(tmp_path: Path) -> None:
    write(tmp_path, "base.yaml", BASE)
    child = """\
extends: base.yaml
name: child
agent: {batch_size: 128}
stages:
  - name: only
    budget: {steps: 300}
"""
    curriculum = load_curriculum(write(tmp_path, "child.yaml", child))
    assert (curriculum.name, curriculum.task, curriculum.envs) == ("child", "push", 4)
    assert (curriculum.agent.batch_size, curriculum.agent.critics) == (128, 2)
    assert (curriculum.eval.every, curriculum.eval.episodes) == (2000, 10)
    assert [stage.name for stage in curriculum.stages] == ["only"]


def test_extends_chain_of_two(tmp_path: Path) -> None:
    write(tmp_path, "base.yaml", BASE)
    write(tmp_path, "middle.yaml", "extends: base.yaml\neval: {episodes: 3}\nagent: {critics: 1}\n")
    curriculum = load_curriculum(
        write(tmp_path, "top.yaml", "extends: middle.yaml\nseed: 7\nagent: {batch_size: 32}\n")
    )
    assert (curriculum.seed, curriculum.eval.every, curriculum.eval.episodes) == (7, 2000, 3)
    assert (curriculum.agent.batch_size, curriculum.agent.critics) == (32, 1)
    assert [stage.name for stage in curriculum.stages] == ["a", "b"]


def test_extends_is_relative_to_the_extending_file(tmp_path: Path) -> None:
    write(tmp_path, "base.yaml", BASE)
    curriculum = load_curriculum(write(tmp_path, "sub/child.yaml", "extends: ../base.yaml\nseed: 5\n"))
    assert (curriculum.name, curriculum.seed) == ("base", 5)


def test_extends_errors_point_into_the_file_that_holds_the_key(tmp_path: Path) -> None:
    base = write(tmp_path, "base.yaml", BASE.replace("critics: 2", "critics: 5"))
    child = write(tmp_path, "child.yaml", "extends: base.yaml\n\nstages:\n  - name: x\n  - name: y\n")
    problems = {problem.path: problem for problem in problems_of(child)}
    assert set(problems) == {"agent", "stages[0].budget", "stages[1].budget"}
    assert (problems["agent"].file, problems["agent"].line) == (base, 4)
    # The child replaced the parent's stages, budgets included: a missing budget is reported at the child's
    # stage, not at the budget of the parent's stage that happened to sit at the same index.
    assert (problems["stages[0].budget"].file, problems["stages[0].budget"].line) == (child, 4)
    assert (problems["stages[1].budget"].file, problems["stages[1].budget"].line) == (child, 5)


def test_extends_cycle_is_an_error(tmp_path: Path) -> None:
    write(tmp_path, "a.yaml", "extends: b.yaml\nname: a\n")
    b = write(tmp_path, "b.yaml", "name: b\nextends: a.yaml\n")
    problem = only_problem(tmp_path / "a.yaml")
    assert (problem.file, problem.line, problem.path) == (b, 2, "extends")
    assert "cycle" in problem.message and "a.yaml" in problem.message


def test_extends_missing_file_names_it(tmp_path: Path) -> None:
    child = write(tmp_path, "child.yaml", "name: c\nextends: nowhere.yaml\n")
    problem = only_problem(child)
    assert (problem.file, problem.line, problem.path) == (child, 2, "extends")
    assert "nowhere.yaml" in problem.message and "no such file" in problem.message


def test_to_yaml_round_trips(tmp_path: Path) -> None:
    text = (
        MINIMAL
        + """\
    env: {objects: 3, correction_rate: 0.25, kinds: [wrong_object, ambiguity], max_episode_steps: 80}
    promote: {success: 0.6, on: corrected, patience: 3, statistic: lower_bound}
    on_budget: stop
agent: {actor_lr: 3e-4, max_grad_norm: 1.0}
"""
    )
    curriculum = load_curriculum(write(tmp_path, "c.yaml", text))
    again = load_curriculum(write(tmp_path, "plan.yaml", curriculum.to_yaml()))
    assert again == curriculum
    assert again.stages[0].env.kinds == ("wrong_object", "ambiguity")


def test_quick_caps_budgets_and_evaluation(tmp_path: Path) -> None:
    text = BASE.replace("steps: 100", "steps: 50000").replace("steps: 200", "steps: 1000")
    curriculum = load_curriculum(write(tmp_path, "c.yaml", text + "learning_starts: 5000\n"))
    quick = curriculum.quick()
    assert quick.name == "base-quick"
    assert [stage.budget.steps for stage in quick.stages] == [1500, 1000]
    assert (quick.eval.every, quick.eval.episodes, quick.learning_starts) == (500, 5, 256)
    assert (curriculum.test.episodes, quick.test.episodes) == (500, QUICK_TEST_EPISODES)
    assert quick.buffer.size == 100_000 and quick.agent.batch_size == 64
    assert curriculum.stages[0].budget.steps == 50000  # the original is untouched


def test_with_overrides(tmp_path: Path) -> None:
    curriculum = load_curriculum(write(tmp_path, "c.yaml", MINIMAL))
    assert (curriculum.with_overrides(seed=9).seed, curriculum.with_overrides(seed=9).envs) == (9, 2)
    assert curriculum.with_overrides(envs=8).envs == 8
    with pytest.raises(CurriculumError) as caught:
        curriculum.with_overrides(envs=100)
    assert [problem.path for problem in caught.value.problems] == ["envs"]


def test_builtin_curriculum() -> None:
    """What ``lanro train --quick`` runs as written: the file a user reads at curricula/quick.yaml, the
    paper's three stages in budgets of a few minutes, and a test set large enough for its figure to mean
    something."""
    curriculum = builtin_curriculum()
    assert curriculum == load_curriculum(Path(__file__).parents[2] / "curricula" / "quick.yaml")
    assert [stage.name for stage in curriculum.stages] == ["single", "corrections", "negations"]
    assert (curriculum.name, curriculum.task, curriculum.max_objects, curriculum.total_steps) == (
        "push-quick",
        "push",
        2,
        7500,
    )
    assert (curriculum.eval.every, curriculum.eval.episodes, curriculum.learning_starts, curriculum.envs) == (
        1000,
        20,
        256,
        2,
    )
    assert curriculum.test.episodes == 100 and curriculum.agent.batch_size == 64
    single, corrections, negations = curriculum.stages
    assert single.promote is not None and (single.promote.success, single.promote.on, single.promote.patience) == (
        0.8,
        "overall",
        2,
    )
    assert corrections.promote is not None and (corrections.promote.success, corrections.promote.on) == (
        0.7,
        "corrected",
    )
    assert (single.env.correction_rate, corrections.env.correction_rate, negations.env.correction_rate) == (0, 0.5, 0.5)
    assert (corrections.env.negations, negations.env.negations, negations.promote) == (False, True, None)
    assert [stage.env.settings().episode_limit for stage in curriculum.stages] == [15, 30, 30]


def test_packaged_curricula_are_the_package_data_the_repository_links_to() -> None:
    packaged = packaged_curricula()
    assert set(packaged) >= {*TASKS, "quick"}
    shipped = Path(__file__).parents[2] / "lanrocli" / "curricula"
    assert all(path.parent.resolve() == shipped.resolve() and path.is_file() for path in packaged.values())
    assert (Path(__file__).parents[2] / "curricula").resolve() == shipped.resolve()


def test_a_curriculum_is_found_by_its_file_or_by_its_packaged_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)  # a directory with no curricula of its own
    packaged = packaged_curricula()
    assert find_curriculum("push") == find_curriculum("push.yaml") == packaged["push"]
    assert load_curriculum(find_curriculum("lift")).task == Task.LIFT  # its extends chain resolves beside it
    own = write(tmp_path, "push", MINIMAL)  # a file that exists wins over a packaged name
    assert find_curriculum("push").resolve() == own.resolve() and find_curriculum(str(own)) == own
    with pytest.raises(CurriculumError) as caught:
        find_curriculum("reech")
    (problem,) = caught.value.problems
    assert problem.file == "reech" and "one of: " + ", ".join(packaged) in problem.message
    assert "did you mean reach?" in problem.message
    with pytest.raises(CurriculumError, match="no such file"):
        find_curriculum("elsewhere/push.yaml")  # a path with a folder is a path, never a name


def test_diff_curricula(tmp_path: Path) -> None:
    old = load_curriculum(write(tmp_path, "c.yaml", MINIMAL))
    assert diff_curricula(old, old.model_copy(), "saved", "file") == ""
    new = load_curriculum(write(tmp_path, "d.yaml", MINIMAL.replace("steps: 1000", "steps: 2000")))
    diff = diff_curricula(old, new, "saved", "file")
    assert "--- saved" in diff and "+++ file" in diff
    assert "-    steps: 1000\n" in diff and "+    steps: 2000\n" in diff


def test_curriculum_model_is_usable_without_a_file() -> None:
    curriculum = Curriculum.model_validate(
        {"name": "x", "task": "lift", "stages": [{"name": "s", "budget": {"steps": 1}}]}
    )
    assert curriculum.stages[0].env.objects == 2


def test_buffer_and_loop_settings_have_their_own_keys(tmp_path: Path) -> None:
    curriculum = load_curriculum(write(tmp_path, "c.yaml", MINIMAL + "buffer: {size: 5000}\nupdates_per_step: 2\n"))
    assert curriculum.buffer.settings() == BufferSettings(size=5000) and curriculum.updates_per_step == 2
    problem = only_problem(write(tmp_path, "bad.yaml", MINIMAL + "buffer:\n  size: 100\n  hindsight_share: 2\n"))
    assert (problem.line, problem.path) == (8, "buffer.hindsight_share")


def test_reading_curricula_loads_neither_torch_nor_pybullet() -> None:
    # A fresh interpreter: in this one, other tests have loaded both long ago.
    code = "import lanrocli.config.curriculum, sys; print(sorted({'torch', 'pybullet'} & set(sys.modules)))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]", f"importing lanrocli.config.curriculum loaded {result.stdout.strip()}"


def test_lanro_check_does_not_load_torch() -> None:
    """``lanro check`` answers at once: torch alone takes seconds to import on a busy machine."""
    path = Path(__file__).parents[2] / "curricula" / "push.yaml"
    command = [sys.executable, "-X", "importtime", "-c", "from lanrocli.cli.app import app; app(prog_name='lanro')"]
    result = subprocess.run([*command, "check", str(path)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "environment steps in all" in result.stdout
    imported = {
        line.rsplit("|", 1)[-1].strip() for line in result.stderr.splitlines() if line.startswith("import time:")
    }
    assert "lanrocli.config.curriculum" in imported and not imported & {"torch", "pybullet"}


HELD_OUT = """\
name: demo
task: push
stages:
  - name: first
    env: {objects: 3, mode: colour_shape, correction_rate: 0.5, negations: true, rare_words: true, max_delay: 10}
    budget: {steps: 1000}
holdout:
  pairs: [red cylinder, yellow cuboid]
  correction_words: [block, brick, barrel]
  late_corrections: [11, 20]
  common_ground: [crimson, jade]
  paraphrase: true
"""


def test_a_holdout_section_is_read_into_the_splits(tmp_path: Path) -> None:
    holdout = load_curriculum(write(tmp_path, "c.yaml", HELD_OUT)).holdout.settings()
    assert holdout.splits == tuple(Split)
    assert holdout.pairs == (ObjectProps("red", "cylinder"), ObjectProps("yellow", "cuboid"))
    assert holdout.late_corrections == (11, 20)


@pytest.mark.parametrize(
    ("line", "bad", "key", "message"),
    [
        (8, "  pairs: [red cylinder, mauve cube]", "holdout.pairs", "unknown colour 'mauve'"),
        (8, "  pairs: [red cylinder, red sphere]", "holdout.pairs", "unknown shape 'sphere'"),
        (9, "  correction_words: [block, brick, cylinderish]", "holdout.correction_words", "'cylinderish' is none"),
        (9, "  correction_words: [block, brick]", "holdout.correction_words", "0 for cylinder"),
        (10, "  late_corrections: [10, 20]", "holdout.late_corrections", "start it at 11"),
        (11, "  common_ground: [crimson, scarlet]", "holdout.common_ground", "every rare word for red"),
        (11, "  common_ground: [mauveish]", "holdout.common_ground", "'mauveish' is none"),
    ],
)
def test_a_bad_holdout_is_located_at_its_key(tmp_path: Path, line: int, bad: str, key: str, message: str) -> None:
    lines = HELD_OUT.splitlines()
    lines[line - 1] = bad
    problem = only_problem(write(tmp_path, "c.yaml", "\n".join(lines) + "\n"))
    assert (problem.file, problem.line, problem.path) == (tmp_path / "c.yaml", line, key)
    assert message in problem.message


def test_a_holdout_that_leaves_no_valid_goal_is_refused(tmp_path: Path) -> None:
    every_cube = ", ".join(f"{colour} cube" for colour in COLOURS)
    text = MINIMAL.replace("task: push", "task: push\nholdout:\n  pairs: [" + every_cube + "]")
    problem = only_problem(write(tmp_path, "c.yaml", text))
    assert (problem.line, problem.path) == (4, "holdout.pairs")
    assert "have no goal" in problem.message and "stages[0]" in problem.message


def test_a_pairs_split_needs_a_last_stage_that_can_show_the_pair(tmp_path: Path) -> None:
    text = MINIMAL.replace("task: push", "task: push\nholdout:\n  pairs: [red cylinder]")  # colour mode: cubes only
    problem = only_problem(write(tmp_path, "c.yaml", text))
    assert problem.path == "holdout.pairs" and "last stage" in problem.message


def test_a_common_ground_split_needs_rare_words_in_the_last_stage(tmp_path: Path) -> None:
    text = HELD_OUT.replace("rare_words: true, ", "")
    problem = only_problem(write(tmp_path, "c.yaml", text))
    assert (problem.line, problem.path) == (11, "holdout.common_ground") and "rare_words" in problem.message


SCREENS = sorted((Path(__file__).resolve().parents[2] / "benchmarks" / "screens").glob("*.yaml"))


@pytest.mark.parametrize("path", SCREENS, ids=lambda p: p.name)
def test_every_screen_in_benchmarks_is_a_valid_curriculum(path: Path) -> None:
    curriculum = load_curriculum(path)
    assert curriculum.name == path.stem and curriculum.stages


OBJECTS = MINIMAL.replace("task: push", "task: push\nagent: {architecture: objects}")
QUESTIONS = OBJECTS + "    env: {objects: 3, mode: colour_shape, correction_rate: 0.5, max_corrections: 2}\n"


def test_a_question_test_loads_with_its_defaults(tmp_path: Path) -> None:
    curriculum = load_curriculum(write(tmp_path, "c.yaml", QUESTIONS + "questions: {level: 0.9}\n"))
    assert curriculum.questions is not None
    assert (curriculum.questions.level, curriculum.questions.episodes, curriculum.questions.steps) == (0.9, 600, 1)
    assert load_curriculum(write(tmp_path, "plain.yaml", QUESTIONS)).questions is None


@pytest.mark.parametrize(
    "text, line, path, message",
    [
        (QUESTIONS + "questions: {penalty: -1}\n", 8, "questions.penalty", "greater than or equal to 0"),
        (QUESTIONS + "questions: {steps: 0}\n", 8, "questions", "is free"),
        (QUESTIONS + "questions: {level: 0.99, calibration_episodes: 50}\n", 8, "questions", "at least 100"),
        (OBJECTS + "questions: {}\n", 7, "questions", "raise max_corrections to 2"),
        (MINIMAL + "    env: {max_corrections: 2}\nquestions: {}\n", 7, "questions", "architecture: objects"),
        (MINIMAL + "    env: {max_corrections: 2, questions: 1}\n", 6, "stages[0].env.questions", "not in training"),
    ],
)
def test_bad_question_settings_are_located(tmp_path: Path, text: str, line: int, path: str, message: str) -> None:
    problem = only_problem(write(tmp_path, "c.yaml", text))
    assert (problem.line, problem.path) == (line, path), problem
    assert message in problem.message
