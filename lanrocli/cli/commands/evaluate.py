"""``lanro eval``: a scripted policy or a trained agent measured, overall and per kind and form of correction;
a trained agent on its run's test episodes, its correction test or a generalisation split, as its run
measured it."""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape

from lanrocli.cli.arguments import device_option, env_changes, err_console, fail, with_env_options
from lanrocli.cli.display.commands import env_summary, print_evaluation
from lanrocli.core.choices import ActingAttention, Instruction, Split
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation.protocols import PROTOCOLS
from lanrocli.tasks import Task

if TYPE_CHECKING:
    from lanrocli.evaluation.blocks import Workers
    from lanrocli.train.testset import Measurement
    from lanrocli.train.trainer import TrainSettings


class PolicyName(StrEnum):
    oracle = "oracle"
    mistaken = "mistaken"
    random = "random"


@with_env_options()
def evaluate_command(
    what: Annotated[
        str,
        typer.Argument(
            metavar="POLICY_OR_CHECKPOINT",
            help="A scripted policy (oracle, mistaken, random); a trained agent: a checkpoint directory, a "
            "pointer such as RUN/stage-2-corrections/best, or a run folder (its latest checkpoint); or your own "
            "policy: package.module:make_policy or path/to/file.py:make_policy, a function that takes the task's "
            "name and returns a policy (docs/benchmark.md), scored on --protocol.",
        ),
    ],
    task: Annotated[
        Task | None, typer.Option(help="Task (scripted policies, default reach; your own policy, required).")
    ] = None,
    episodes: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Number of episodes (default: a checkpoint's test.episodes, else 100; with --protocol, the "
            "protocol's, and for its correction test the most it plays).",
        ),
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option(
            min=0,
            help="Episode i uses seed SEED + i. Default: a checkpoint's held-out test episodes (the ones report.md "
            "quotes), 0 for a scripted policy.",
        ),
    ] = None,
    instruction: Annotated[
        Instruction,
        typer.Option(
            help="The sentence the agent reads: the instructor's (true), none (blank), or one naming another "
            "object on the table (other; success is the task on that object).",
        ),
    ] = Instruction.TRUE,
    device: Annotated[
        str | None,
        typer.Option(
            callback=device_option, help="cpu, cuda or cuda:N for a trained agent (default: cuda if available)."
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object on stdout.")] = False,
    gif: Annotated[Path | None, typer.Option(help="Write the first episodes as an animated GIF here.")] = None,
    correction_test: Annotated[
        bool,
        typer.Option(
            "--correction-test",
            help="A trained agent on its stage's correction test, as its run measured it: every episode a "
            "correction episode (half the spoken corrections negations, where the stage has them), on episodes "
            "of their own, until enough corrections and negations were spoken to judge each kind and form. "
            "--episodes caps the episodes.",
        ),
    ] = False,
    second_corrections: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="With --correction-test: go on until this many episodes had a second correction spoken too (a "
            "stage with chains of corrections), to judge the agent after one. --episodes caps the episodes.",
        ),
    ] = None,
    question_test: Annotated[
        bool,
        typer.Option(
            "--question-test",
            help="A trained agent asking 'which one?' by its calibrated rule (docs/questions.md), and the same agent "
            "with questions off, on held-out episodes of their own: every episode a correction episode of any kind, "
            "so a quarter are clear. Per kind: episodes with a question, questions per episode, success and "
            "actions on a wrong object. --episodes sets how many (default 600).",
        ),
    ] = False,
    level: Annotated[
        float | None,
        typer.Option(
            min=0.0,
            max=1.0,
            help="With --question-test: the share of scenes on which the rule must keep the meant object (default "
            "0.97, or the curriculum's questions.level).",
        ),
    ] = None,
    split: Annotated[
        Split | None,
        typer.Option(
            help="A trained agent on one generalisation split of its run's holdout (docs/generalisation.md), on the "
            "split's own held-out episodes, as its run measured it; --episodes sets how many (default: test.episodes).",
        ),
    ] = None,
    acting_attention: Annotated[
        ActingAttention | None,
        typer.Option(
            help="How a trained agent with object attention reads the scene as it acts: the attention-weighted mix "
            "of the objects (soft) or the one object it attends to most (argmax). Default: the agent's own rule.",
        ),
    ] = None,
    protocol: Annotated[
        str | None,
        typer.Option(
            help="Score on a benchmark protocol, the same episodes for every policy (docs/benchmark.md): "
            + ", ".join(PROTOCOLS)
            + ". Default for your own policy: test.",
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Processes that share the episodes of a protocol or of a trained agent's measurement (default: the "
            "cores this process may use); the figures do not depend on it.",
        ),
    ] = None,
    address: Annotated[
        str | None,
        typer.Option(help="With --protocol: the Ray cluster that plays the episodes (auto, or ray://HOST:PORT)."),
    ] = None,
    **env_options: Any,
) -> None:
    """Evaluate a scripted policy or a trained agent, overall and per kind and form of correction.

    Success on all episodes, on correction episodes, where a correction was spoken, per kind and form of
    correction, with 95% intervals. For a checkpoint, the environment defaults to the stage it was trained on
    and the episodes to that stage's held-out test episodes; options change them."""
    from lanrocli.envs.env import LanroEnv
    from lanrocli.envs.policies import make_policy
    from lanrocli.evaluation.evaluate import evaluate

    changes = env_changes(env_options)
    if protocol is not None or ":" in what:
        others = correction_test or split or seed is not None or instruction is not Instruction.TRUE or gif or changes
        if others or second_corrections is not None or acting_attention is not None:
            raise fail(
                "a benchmark protocol fixes its episodes, sentences and settings; leave out --correction-test, "
                "--second-corrections, --split, --seed, --instruction, --gif, --acting-attention and the "
                "environment options"
            )
        _score(what, task, protocol or "test", episodes, device, workers, address, as_json)
        return
    if address is not None:
        raise fail("--address plays a benchmark protocol's episodes on a Ray cluster; add --protocol")
    if workers is not None and gif is not None:
        raise fail("--gif records its frames in this process; leave out --workers")
    if workers is not None and what in {p.value for p in PolicyName}:
        raise fail("--workers shares the episodes of a protocol or a trained agent; add --protocol")
    count = workers or len(os.sched_getaffinity(0))
    if level is not None and not question_test:
        raise fail("--level is the calibrated rule's level in the question test; add --question-test")
    if question_test:
        if correction_test or split or seed is not None or instruction is not Instruction.TRUE or gif:
            raise fail(
                "--question-test runs episodes of its own, with questions and without; leave out --correction-test, "
                "--split, --seed, --instruction and --gif"
            )
        _question_test(what, task, episodes, level, device, changes, as_json, count)
        return
    if correction_test and (seed is not None or instruction is not Instruction.TRUE or gif is not None):
        raise fail(
            "--correction-test runs episodes of its own, as the sentence the instructor speaks; leave out "
            "--seed, --instruction and --gif"
        )
    if second_corrections is not None and not correction_test:
        raise fail("--second-corrections sets how long the correction test runs; add --correction-test")
    if split is not None and (
        correction_test or seed is not None or instruction is not Instruction.TRUE or gif or changes
    ):
        raise fail(
            "--split runs the split's own episodes and settings; leave out --correction-test, --seed, "
            "--instruction, --gif and the environment options"
        )
    if what in {p.value for p in PolicyName}:
        if split is not None:
            raise fail("--split measures a trained agent on what its run held out; a scripted policy has no run")
        if correction_test:
            raise fail(
                "--correction-test measures a trained agent on its run's held-out seeds; a scripted policy has none"
            )
        if instruction is not Instruction.TRUE:
            raise fail("--instruction changes what a trained agent reads; scripted policies read no sentence")
        if changes.get("questions"):
            raise fail("--questions lets a trained agent ask by its calibrated rule; scripted policies ask none")
        if acting_attention is not None:
            raise fail(
                "--acting-attention changes how a trained agent reads the scene; scripted policies attend to nothing"
            )
        task_name = task or Task.REACH
        first = 0 if seed is None else seed
        try:
            env_settings = EnvSettings(**changes)
            env = LanroEnv(task_name, env_settings, render_mode="rgb_array" if gif else None)
        except ValueError as error:
            raise fail(f"{error} (see 'lanro eval --help')") from None
        try:
            report = evaluate(env, make_policy(what, task_name), episodes or 100, first, gif)
        finally:
            env.close()
        record = {"policy": what, "task": task_name, "env": env_settings.to_dict(), **report.as_dict()}
        where = f"seed {first}"
    elif split is not None:
        agent = _trained_agent(what)
        measurement = _measure_checkpoint(
            agent, task, device, _split_test(agent, split, episodes, acting_attention), count
        )
        report, record, task_name, env_settings = (
            measurement.report,
            measurement.record,
            measurement.settings.task,
            measurement.env,
        )
        where = f"the {split.value} split's held-out episodes"
    elif correction_test:
        agent = _trained_agent(what)
        measurement = _measure_checkpoint(
            agent, task, device, _correction_test(agent, changes, episodes, second_corrections, acting_attention), count
        )
        report, record, task_name, env_settings = (
            measurement.report,
            measurement.record,
            measurement.settings.task,
            measurement.env,
        )
        quota = record["quota"]
        negations = f" and {quota['negations']} negations" if quota["negations"] else ""
        seconds = f" and {quota['second']} second corrections" if quota.get("second") else ""
        met = "reached" if record["quota_met"] else f"not reached in {quota['episodes']} episodes"
        where = f"correction test ({quota['spoken']} spoken corrections{negations}{seconds}: {met})"
    else:
        agent = _trained_agent(what)
        measurement = _measure_checkpoint(
            agent, task, device, _test(agent, changes, episodes, seed, instruction, gif, acting_attention), count
        )
        report, record, task_name, env_settings = (
            measurement.report,
            measurement.record,
            measurement.settings.task,
            measurement.env,
        )
        where = "held-out test episodes" if measurement.held_out else f"seed {measurement.first_seed}"
        if instruction is not Instruction.TRUE:
            where += f", instruction {instruction}"
    if record.get("acting_attention") == ActingAttention.ARGMAX:
        where += ", acting on the object it attends to most"
    if record.get("unknown_words"):
        unknown = ", ".join(record["unknown_words"])
        err_console.print(
            f"[bold yellow]warning:[/] {escape(f'the agent never learned the words {unknown}: it reads each as <unk>')}"
        )
    if as_json:
        typer.echo(json.dumps(record))
        return
    print_evaluation(report, f"{what} on {task_name}, {env_summary(env_settings)}, {where}")
    if split is not None:
        from lanrocli.evaluation.splits import control_lines

        for line in control_lines(split, record):
            Console().print(line, highlight=False, soft_wrap=True)
    if gif:
        Console().print(f"wrote {gif}")


def _score(
    what: str,
    task: Task | None,
    protocol: str,
    episodes: int | None,
    device: str | None,
    workers: int | None,
    address: str | None,
    as_json: bool,
) -> None:
    """``lanro eval ... --protocol``: a scripted policy, a trained agent or your own, on a benchmark protocol."""
    from lanrocli.evaluation.benchmark import score
    from lanrocli.evaluation.protocols import PROTOCOL_VERSION
    from lanrocli.evaluation.rollout import PolicyError

    policy: Any
    if ":" in what:
        if task is None:
            raise fail(f"{what} makes a policy for a task: add --task (one of {', '.join(t.value for t in Task)})")
        policy, task_name = what, task.value
    elif what in {p.value for p in PolicyName}:
        from lanrocli.envs.policies import make_policy

        task_name = (task or Task.REACH).value
        policy = make_policy(what, task_name)
    else:
        from lanrocli.train.trainer import load_policy, pick_device

        path = _trained_agent(what)
        if not path.exists():
            raise fail(f"{path} is neither a policy nor an existing checkpoint path")
        from lanrocli.train.errors import CheckpointError

        try:
            settings, policy = load_policy(path, pick_device(device))
        except (CheckpointError, ValueError, KeyError) as error:
            raise fail(f"cannot load a trained agent from {path}: {error}") from None
        if task is not None and task != settings.task:
            raise fail(f"{path} was trained on {settings.task}; it cannot be scored on {task}")
        task_name = settings.task
    count = workers or len(os.sched_getaffinity(0))
    try:
        report, record = score(
            policy, task_name, protocol, episodes=episodes, workers=count, address=address, label=what
        )
    except PolicyError as error:
        raise fail(f"{what}: {error}") from None
    except (TypeError, ValueError) as error:
        raise fail(f"{what}: {error}") from None
    if as_json:
        typer.echo(json.dumps(record))
        return
    described = PROTOCOLS[protocol].description
    print_evaluation(report, f"{what} on {task_name}, protocol {protocol} (version {PROTOCOL_VERSION}): {described}")
    if "split" in record:
        from lanrocli.evaluation.splits import control_lines

        for line in control_lines(Split(protocol), record):
            Console().print(line, highlight=False, soft_wrap=True)


def _question_test(
    what: str,
    task: Task | None,
    episodes: int | None,
    level: float | None,
    device: str | None,
    changes: dict[str, Any],
    as_json: bool,
    workers: int,
) -> None:
    """``lanro eval CHECKPOINT --question-test``."""
    from lanrocli.cli.display.commands import print_questions
    from lanrocli.train.testset import question_test, question_test_settings

    if what in {p.value for p in PolicyName} or ":" in what:
        raise fail("--question-test measures a trained agent's questions; a scripted policy asks none")
    agent = _trained_agent(what)
    try:
        test = question_test_settings(agent, episodes=episodes, level=level)
    except ValueError as error:
        raise fail(f"{error} (see 'lanro eval --help')") from None

    def run(device: Any, check: Check, pool: Workers) -> Measurement:
        return question_test(agent, test, device, changes, check=check, workers=pool)

    measurement = _measure_checkpoint(agent, task, device, run, workers)
    if as_json:
        typer.echo(json.dumps(measurement.record))
        return
    title = f"{what} on {measurement.settings.task}, {env_summary(measurement.env)}, question test"
    print_questions(measurement.record, title)


Check = Callable[["TrainSettings", EnvSettings], None]
Measure = Callable[[Any, Check, "Workers"], "Measurement"]
"""How ``lanro eval`` measures a checkpoint, given the torch device, the check of its settings and the
workers that play its episodes."""


def _test(
    path: Path,
    overrides: dict[str, Any],
    episodes: int | None,
    seed: int | None,
    shown: Instruction,
    gif: Path | None,
    acting: ActingAttention | None,
) -> Measure:
    """The checkpoint at ``path`` on its test episodes, or on others as the options ask."""
    from lanrocli.train.testset import measure

    def run(device: Any, check: Check, pool: Workers) -> Measurement:
        count = episodes or _test_episodes(path)
        return measure(
            path, count, device, overrides, seed, shown, gif, check=check, acting_attention=acting, workers=pool
        )

    return run


def _correction_test(
    path: Path, overrides: dict[str, Any], episodes: int | None, second: int | None, acting: ActingAttention | None
) -> Measure:
    """The checkpoint at ``path`` on the correction test its run made: the quota sized like its test, at most
    ``episodes`` episodes where given, and on until ``second`` second corrections were spoken where given."""
    from lanrocli.evaluation.quota import CORRECTION_QUOTA
    from lanrocli.train.testset import correction_test

    def run(device: Any, check: Check, pool: Workers) -> Measurement:
        quota = CORRECTION_QUOTA.scaled(_test_episodes(path))
        if episodes is not None:
            quota = dataclasses.replace(quota, episodes=episodes)
        if second is not None:
            quota = dataclasses.replace(quota, second=second)
        return correction_test(path, quota, device, overrides, check=check, acting_attention=acting, workers=pool)

    return run


def _split_test(path: Path, split: Split, episodes: int | None, acting: ActingAttention | None) -> Measure:
    """The checkpoint at ``path`` on one generalisation split of its run's holdout."""
    from lanrocli.train.testset import split_test

    def run(device: Any, check: Check, pool: Workers) -> Measurement:
        count = episodes or _test_episodes(path)
        return split_test(path, split, count, device, check=check, acting_attention=acting, workers=pool)

    return run


def _trained_agent(what: str) -> Path:
    """The checkpoint path ``what`` names, or the shipped agent of that name (``lanro eval push``)."""
    from lanrocli.pretrained import agent_path
    from lanrocli.train.errors import CheckpointError

    try:
        return agent_path(Path(what))
    except CheckpointError as error:
        raise fail(f"{error}; or name a scripted policy (oracle, mistaken, random)") from None


def _measure_checkpoint(path: Path, task: Task | None, device: str | None, run: Measure, workers: int) -> Measurement:
    """The trained agent at ``path`` measured as ``run`` does over ``workers`` processes; every problem is a
    clear error."""
    from lanrocli.evaluation.blocks import MeasuringError, Workers
    from lanrocli.train.errors import CheckpointError
    from lanrocli.train.trainer import pick_device

    if not path.exists():
        raise fail(f"{path} is neither a scripted policy (oracle, mistaken, random) nor an existing checkpoint path")

    def check(settings: TrainSettings, env_settings: EnvSettings) -> None:
        if task is not None and task != settings.task:
            raise fail(f"{path} was trained on {settings.task}; it cannot be evaluated on {task}")
        if env_settings.objects > settings.slots:
            raise fail(f"{path} observes at most {settings.slots} objects; --objects must not exceed that")

    try:
        with Workers(workers) as pool:
            return run(pick_device(device), check, pool)
    except MeasuringError as error:
        raise fail(str(error), code=1) from None
    except (CheckpointError, KeyError) as error:
        raise fail(f"cannot load a trained agent from {path}: {error}") from None
    except ValueError as error:
        raise fail(f"{error} (see 'lanro eval --help')") from None


def _test_episodes(path: Path) -> int:
    """The test-set size of the run that ``path`` belongs to, so ``lanro eval`` repeats what report.md quotes."""
    from lanrocli.config.curriculum import Curriculum, CurriculumError, load_curriculum
    from lanrocli.config.sections import HeldOutConfig
    from lanrocli.train.checkpoint import resolve_checkpoint
    from lanrocli.train.runfolder import CONFIG

    config = resolve_checkpoint(path).parent.parent / CONFIG
    try:
        plan: Curriculum = load_curriculum(config)
        return plan.test.episodes
    except CurriculumError:
        return HeldOutConfig().episodes
