"""A trained agent measured on episodes: by default its stage's held-out test episodes.

The run measures the ``last`` and ``best`` agents of every stage here when the stage ends, and ``lanro eval``
measures any checkpoint here, so the two give the same record for the same checkpoint and episodes: the
record is what ``test.json`` holds and what ``lanro eval --json`` prints.

The ordinary test holds few spoken corrections (about one episode in five, fewer of each kind and form), too
few to judge how an agent follows each. The correction test makes every episode a correction episode, half
of the spoken corrections negations where the stage has them, and runs held-out episodes of its own until
enough corrections and negations were spoken (:class:`~lanrocli.evaluation.quota.CorrectionQuota`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lanrocli.agent.policy import AgentPolicy
from lanrocli.config.sections import QuestionsConfig
from lanrocli.core.choices import ActingAttention, Instruction, Split
from lanrocli.core.seeds import (
    calibration_seed,
    correction_test_seed,
    held_out_seed,
    question_test_seed,
    split_test_seed,
)
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation.asking import (
    AskingPolicy,
    Calibration,
    asked_by_fits,
    calibrate,
    kept,
    questions_record,
    weights_on_meant,
)
from lanrocli.evaluation.blocks import Workers, play
from lanrocli.evaluation.evaluate import SIDE_BY_SIDE, EvaluationReport, evaluate
from lanrocli.evaluation.metrics import Rate
from lanrocli.evaluation.quota import CORRECTION_QUOTA, CorrectionQuota, correction_changes
from lanrocli.evaluation.splits import CONTROL, CONTROLLED, DROP, paired_drops, split_changes
from lanrocli.language.vocabulary import unlearned_words
from lanrocli.train.checkpoint import resolve_checkpoint
from lanrocli.train.runfolder import BEST, CORRECTION_TEST, LANGUAGE, LAST, QUESTION_TEST, SPLITS
from lanrocli.train.trainer import TrainSettings, load_policy


@dataclass(frozen=True)
class Measurement:
    """What one measurement of a checkpoint found, and the record of it for files and ``--json``."""

    settings: TrainSettings
    env: EnvSettings
    first_seed: int
    held_out: bool
    report: EvaluationReport
    record: dict[str, Any]


def checkpoint_name(directory: Path) -> str:
    """A checkpoint as its run names it (``stage-1-single/step-0000010000``), whatever path led to it."""
    return f"{directory.parent.name}/{directory.name}"


@dataclass(frozen=True)
class _Loaded:
    """A checkpoint's deterministic policy and the environment settings it is to be measured on: its
    run's holdout always applies, and ``split`` makes the episodes those of one generalisation split."""

    directory: Path
    settings: TrainSettings
    policy: AgentPolicy
    env: EnvSettings
    split: Split | None = None


def _load(
    path: Path,
    device: str | torch.device,
    changes: Callable[[EnvSettings], Mapping[str, Any]],
    check: Callable[[TrainSettings, EnvSettings], None] | None,
    split: Split | None = None,
    acting_attention: ActingAttention | None = None,
) -> _Loaded:
    """Load the checkpoint at ``path``; its stage's settings as evaluation sees them (neutral starts) are
    changed by what ``changes`` makes of them, and ``check`` may refuse the result before anything runs;
    ``split``, which the checkpoint's holdout must define, makes the episodes that split's;
    ``acting_attention`` replaces the agent's rule for reading the scene as it acts."""
    directory = resolve_checkpoint(path)
    settings, policy = load_policy(directory, device)
    if acting_attention is not None:
        policy.agent.act_by(acting_attention)
    settings.holdout.check_split(split)
    stage = settings.env.for_evaluation()
    env_settings = stage.replace(**changes(stage))
    if check is not None:
        check(settings, env_settings)
    return _Loaded(directory, settings, policy, env_settings, split)


def _env(loaded: _Loaded, gif: Path | None = None) -> Callable[[], LanroEnv]:
    settings = loaded.settings
    return functools.partial(
        LanroEnv,
        settings.task,
        loaded.env,
        object_slots=settings.slots,
        render_mode="rgb_array" if gif else None,
        vocabulary=loaded.policy.vocabulary,
        holdout=settings.holdout,
        split=loaded.split,
    )


def _run(
    loaded: _Loaded,
    episodes: int,
    first: int,
    instruction: Instruction = Instruction.TRUE,
    gif: Path | None = None,
    progress: Callable[[int], None] | None = None,
    enough: Callable[[EvaluationReport], bool] | None = None,
    policy: AskingPolicy | None = None,
    workers: Workers | None = None,
) -> EvaluationReport:
    """``loaded``'s episodes played by its agent, or by ``policy`` (the agent asking questions), over
    ``workers`` (default: in this process); a GIF's frames are recorded in this process."""
    chosen = policy or loaded.policy
    if gif is None:
        workers = workers or Workers()
        try:
            source = workers.source(chosen)
        except ValueError:  # an agent whose update was compiled does not pickle: this process plays the blocks
            workers = Workers()
            source = workers.source(chosen)
        return play(workers, source, _env(loaded), episodes, first, instruction, enough, progress)
    envs = [_env(loaded, gif)() for _ in range(SIDE_BY_SIDE)]
    try:
        return evaluate(envs, chosen, episodes, first, gif, progress, instruction, enough)
    finally:
        for env in envs:
            env.close()


def _calibrated(loaded: _Loaded, level: float, episodes: int) -> Calibration:
    """The rule for asking fitted to ``loaded``'s agent on calibration scenes of its stage."""
    env = _env(loaded)()
    try:
        first = calibration_seed(loaded.settings.seed, loaded.settings.stage)
        return calibrate(env, loaded.policy, episodes, first, level, SIDE_BY_SIDE)
    finally:
        env.close()


def _record(
    loaded: _Loaded, episodes_from: dict[str, Any], instruction: Instruction, report: EvaluationReport
) -> dict[str, Any]:
    return {
        "checkpoint": checkpoint_name(loaded.directory),
        "task": loaded.settings.task,
        "env": loaded.env.to_dict(),
        "episodes_from": episodes_from,
        "instruction": instruction.value,
        "acting_attention": loaded.policy.agent.settings.acting_attention,
        "unknown_words": unlearned_words(loaded.policy.vocabulary),
        **report.as_dict(),
    }


def measure(
    path: Path,
    episodes: int,
    device: str | torch.device = "cpu",
    overrides: Mapping[str, Any] | None = None,
    seed: int | None = None,
    instruction: Instruction = Instruction.TRUE,
    gif: Path | None = None,
    progress: Callable[[int], None] | None = None,
    check: Callable[[TrainSettings, EnvSettings], None] | None = None,
    acting_attention: ActingAttention | None = None,
    workers: Workers | None = None,
) -> Measurement:
    """Run the deterministic policy of the checkpoint at ``path`` (a checkpoint, pointer or run folder).

    The environment is the checkpoint's stage as evaluation sees it (neutral starts), changed by
    ``overrides`` (fields of ``EnvSettings``); the episodes are the stage's test episodes unless ``seed`` asks
    for others (episode i then uses ``seed + i``). ``check`` may refuse the resolved settings (raise) before
    anything runs; ``acting_attention`` replaces the agent's rule for reading the scene as it acts. With
    questions in the settings, the agent asks by its calibrated rule (:func:`calibrated_rule`). ``workers``
    play the episodes (default: this process), with the same figures however many there are.
    """
    loaded = _load(path, device, lambda _: overrides or {}, check, acting_attention=acting_attention)
    held_out = seed is None
    first = held_out_seed(loaded.settings.seed, loaded.settings.stage) if seed is None else seed
    asking, asked = _asking(loaded, device)
    report = _run(loaded, episodes, first, instruction, gif, progress, policy=asking, workers=workers)
    record = _record(loaded, {"test_set": held_out, "first_seed": first}, instruction, report) | asked(report)
    return Measurement(loaded.settings, loaded.env, first, held_out, report, record)


def _correction_settings(overrides: Mapping[str, Any]) -> Callable[[EnvSettings], dict[str, Any]]:
    """The correction test's changes to a stage (:func:`correction_changes`), changed by ``overrides``."""
    return lambda stage: {**correction_changes(stage), **overrides}


def correction_test(
    path: Path,
    quota: CorrectionQuota = CORRECTION_QUOTA,
    device: str | torch.device = "cpu",
    overrides: Mapping[str, Any] | None = None,
    progress: Callable[[int], None] | None = None,
    check: Callable[[TrainSettings, EnvSettings], None] | None = None,
    acting_attention: ActingAttention | None = None,
    workers: Workers | None = None,
) -> Measurement:
    """The checkpoint at ``path`` on its stage's correction-test episodes until ``quota`` is met.

    The episodes come from a seed stream of their own (``correction_test_seed``), so none is an episode of
    training, evaluation or the ordinary test; they and the quota fix where it stops, so the same checkpoint
    always gives the same record. The record is ``measure``'s with ``quota`` and whether it was met (and,
    with questions in ``overrides``, the questions asked by the calibrated rule).
    """
    loaded = _load(path, device, _correction_settings(overrides or {}), check, acting_attention=acting_attention)
    first = correction_test_seed(loaded.settings.seed, loaded.settings.stage)
    negations, chains = loaded.env.negations, loaded.env.max_corrections > 1
    if quota.second and not chains:
        raise ValueError(f"a second correction is never spoken in {path}'s stage: it corrects at most once an episode")
    asking, asked = _asking(loaded, device)

    def enough(report: EvaluationReport) -> bool:
        return quota.met(report, negations, chains)

    report = _run(loaded, quota.episodes, first, progress=progress, enough=enough, policy=asking, workers=workers)
    record = {
        **_record(loaded, {"correction_test": True, "first_seed": first}, Instruction.TRUE, report),
        **asked(report),
        "quota": {**asdict(quota), "negations": quota.negations if negations else 0},
        "quota_met": quota.met(report, negations, chains),
    }
    return Measurement(loaded.settings, loaded.env, first, True, report, record)


def split_test(
    path: Path,
    split: Split,
    episodes: int,
    device: str | torch.device = "cpu",
    progress: Callable[[int], None] | None = None,
    check: Callable[[TrainSettings, EnvSettings], None] | None = None,
    acting_attention: ActingAttention | None = None,
    workers: Workers | None = None,
) -> Measurement:
    """The checkpoint at ``path`` on ``episodes`` held-out episodes of one generalisation split of its run's
    holdout, on a seed stream of the split's own; for a split in ``CONTROLLED`` the record's ``control`` is
    the same seeds played with nothing held out."""
    loaded = _load(path, device, split_changes(split), check, split, acting_attention)
    first = split_test_seed(loaded.settings.seed, loaded.settings.stage, split)
    report = _run(loaded, episodes, first, progress=progress, workers=workers)
    record = {
        **_record(loaded, {"split": split.value, "first_seed": first}, Instruction.TRUE, report),
        "split": split.value,
    }
    if split in CONTROLLED:
        control = replace(loaded, split=None)
        played = _run(control, episodes, first, progress=progress, workers=workers)
        record[CONTROL] = _record(control, {"control_of": split.value, "first_seed": first}, Instruction.TRUE, played)
        record[DROP] = paired_drops(split, report.results, played.results)
    return Measurement(loaded.settings, loaded.env, first, True, report, record)


def _asking_episodes(
    path: Path,
    device: str | torch.device,
    test: QuestionsConfig,
    overrides: Mapping[str, Any] | None = None,
    check: Callable[[TrainSettings, EnvSettings], None] | None = None,
) -> _Loaded:
    """The checkpoint at ``path`` with its last stage as the question test plays it. Where the run's holdout
    keeps rare colour words out of training, the common-ground episodes speak those, as a person might."""
    loaded = _load(path, device, lambda _: {**test.changes(), **(overrides or {})}, check)
    if Split.COMMON_GROUND in loaded.settings.holdout.splits:
        loaded = replace(loaded, split=Split.COMMON_GROUND)
    return loaded


def _asking(
    loaded: _Loaded, device: str | torch.device
) -> tuple[AskingPolicy | None, Callable[[EvaluationReport], dict[str, Any]]]:
    """Where ``loaded``'s settings let the agent ask: the agent asking by its calibrated rule, and what a
    record adds of its questions (the calibration and the figures per kind of episode)."""
    if not loaded.env.questions:
        return None, lambda _: {}
    calibration = calibrated_rule(loaded.directory, device)
    return AskingPolicy(loaded.policy, calibration.threshold), lambda report: {
        "calibration": calibration.as_dict(),
        "questions": questions_record(report.results),
    }


def calibrated_rule(path: Path, device: str | torch.device = "cpu") -> Calibration:
    """The rule for asking of the checkpoint at ``path``, calibrated as its question test calibrates it."""
    test = question_test_settings(path)
    return _calibrated(_asking_episodes(path, device, test), test.level, test.calibration_episodes)


def question_test_settings(path: Path, episodes: int | None = None, level: float | None = None) -> QuestionsConfig:
    """The question test of the run that ``path`` belongs to (its curriculum's ``questions``, else the
    defaults), with ``episodes`` and ``level`` changed where given."""
    from lanrocli.config.curriculum import CurriculumError, load_curriculum
    from lanrocli.train.runfolder import CONFIG

    try:
        found = load_curriculum(resolve_checkpoint(path).parent.parent / CONFIG).questions
    except CurriculumError:
        found = None
    changes = {key: value for key, value in (("episodes", episodes), ("level", level)) if value is not None}
    return QuestionsConfig.model_validate({**(found or QuestionsConfig()).model_dump(), **changes})


def question_test(
    path: Path,
    test: QuestionsConfig | None = None,
    device: str | torch.device = "cpu",
    overrides: Mapping[str, Any] | None = None,
    progress: Callable[[int], None] | None = None,
    check: Callable[[TrainSettings, EnvSettings], None] | None = None,
    workers: Workers | None = None,
) -> Measurement:
    """The checkpoint at ``path`` asking questions by the calibrated rule (:mod:`lanrocli.evaluation.asking`)
    on held-out episodes of their own, and the same agent on the same episodes with questions off.

    The record is ``measure``'s for the episodes with questions, with ``calibration``; ``coverage``, the
    share of the test's scenes on which the rule kept the meant object (the level it was fitted to hold);
    ``questions`` and ``questions_off``, the figures per kind of episode; ``asked_by_fits``; and ``off``,
    the record of the episodes without questions.
    """
    test = test or QuestionsConfig()
    loaded = _asking_episodes(path, device, test, overrides, check)
    first = question_test_seed(loaded.settings.seed, loaded.settings.stage)
    calibration = _calibrated(loaded, test.level, test.calibration_episodes)
    asking = AskingPolicy(loaded.policy, calibration.threshold)
    report = _run(loaded, test.episodes, first, progress=progress, policy=asking, workers=workers)
    off = replace(loaded, env=loaded.env.replace(questions=0))
    played = _run(off, test.episodes, first, progress=progress, workers=workers)
    env = _env(loaded)()
    try:
        meant = weights_on_meant(env, loaded.policy, test.episodes, first, SIDE_BY_SIDE)
    finally:
        env.close()
    unasked = [r for r in report.results if not r.questions]
    record = {
        **_record(loaded, {"question_test": True, "first_seed": first}, Instruction.TRUE, report),
        "calibration": calibration.as_dict(),
        "coverage": Rate(len(meant), int(kept(np.array(meant), calibration.threshold).sum())).as_dict(),
        "acted_without_asking": Rate(len(unasked), sum(r.success for r in unasked)).as_dict(),
        "questions": questions_record(report.results),
        "questions_off": questions_record(played.results),
        "asked_by_fits": asked_by_fits(report.results),
        "off": _record(off, {"question_test": True, "first_seed": first}, Instruction.TRUE, played),
    }
    return Measurement(loaded.settings, loaded.env, first, True, report, record)


# -- a stage's agents --------------------------------------------------------------------------------------


class TestsStopped(Exception):
    """A stop request arrived while a stage's agents were being tested: nothing of the tests is kept, and a
    resumed run measures the stage again from its first episode."""


def measure_stage(
    folder: Path,
    episodes: int,
    device: str | torch.device,
    final: bool,
    splits: tuple[Split, ...],
    should_stop: Callable[[], bool] = lambda: False,
    questions: QuestionsConfig | None = None,
    workers: int = 1,
) -> tuple[dict[str, Any], dict[str, dict[str, float | int | None]]]:
    """The ``test.json`` record of the stage in ``folder`` and its figures by agent: its last and best agents
    on its held-out test episodes, read back from their checkpoints. The run's ``final`` stage also has its
    last agent read a blank and another object's sentence, its agents on the correction test, sized like the
    test (``CorrectionQuota.scaled``), on each generalisation split in ``splits``, as many episodes as the
    test (as many again for a split's control), and with ``questions`` on the question test. ``workers``
    processes share the episodes of every measurement (:mod:`lanrocli.evaluation.blocks`). A stop request
    raises :class:`TestsStopped`, heard after every episode and, while workers play, at least every half
    second: the tests of a last stage take minutes, longer than a cluster's scheduler waits after it asks a
    job to stop."""

    def progress(_: int) -> None:
        if should_stop():
            raise TestsStopped(f"stopped while testing the agents of {folder.name}")

    with Workers(workers) as pool:
        return _measured(folder, episodes, device, final, splits, questions, progress, pool)


def _measured(
    folder: Path,
    episodes: int,
    device: str | torch.device,
    final: bool,
    splits: tuple[Split, ...],
    questions: QuestionsConfig | None,
    progress: Callable[[int], None],
    pool: Workers,
) -> tuple[dict[str, Any], dict[str, dict[str, float | int | None]]]:
    options: dict[str, Any] = {"progress": progress, "workers": pool}
    agents = [name for name in (LAST, BEST) if (folder / name).is_file()]
    tested = once_per_agent(folder, agents, lambda path: measure(path, episodes, device, **options))
    record: dict[str, Any] = records(tested)
    figures = {name: measurement.report.metrics() for name, measurement in tested.items()}
    if final:
        plain = {"correction_rate": 0.0}
        language = {
            shown.value: measure(folder / LAST, episodes, device, plain, instruction=shown, **options)
            for shown in Instruction
        }
        record[LANGUAGE] = records(language)
        quota = CORRECTION_QUOTA.scaled(episodes)
        corrections = once_per_agent(folder, agents, lambda path: correction_test(path, quota, device, **options))
        record[CORRECTION_TEST] = records(corrections)
        measured = {LANGUAGE: language, CORRECTION_TEST: corrections}
        if splits:
            split_tests = {
                split.value: once_per_agent(
                    folder, agents, lambda path, s=split: split_test(path, s, episodes, device, **options)
                )
                for split in splits
            }
            record[SPLITS] = {split: records(by_agent) for split, by_agent in split_tests.items()}
            measured |= {f"{SPLITS}/{split}": by_agent for split, by_agent in split_tests.items()}
        if questions is not None:
            asked = once_per_agent(folder, agents, lambda path: question_test(path, questions, device, **options))
            record[QUESTION_TEST] = records(asked)
            measured[QUESTION_TEST] = asked
        for kind, by_name in measured.items():
            figures |= {f"{kind}/{name}": measurement.report.metrics() for name, measurement in by_name.items()}
    return record, figures


def once_per_agent(folder: Path, names: list[str], measured: Callable[[Path], Measurement]) -> dict[str, Measurement]:
    """``measured`` of each pointer of ``names`` in a stage's ``folder``, measured once per agent: ``best``
    taken at the stage's last evaluation is the ``last`` agent (the same step, the same weights), and its
    measurement is the other's, its record under its own checkpoint name."""
    measurements: dict[str, Measurement] = {}
    by_step: dict[str, Measurement] = {}
    for name in names:
        directory = resolve_checkpoint(folder / name)
        step = directory.name.rsplit("-", 1)[-1]
        if step not in by_step:
            by_step[step] = measured(directory)
        found = by_step[step]
        record = {**found.record, "checkpoint": checkpoint_name(directory)}
        measurements[name] = replace(found, record=record)
    return measurements


def records(measurements: dict[str, Measurement]) -> dict[str, dict[str, Any]]:
    return {name: measurement.record for name, measurement in measurements.items()}
