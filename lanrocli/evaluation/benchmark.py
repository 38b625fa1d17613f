"""Score any policy (:mod:`lanrocli.evaluation.adapters`) on a benchmark protocol
(:mod:`lanrocli.evaluation.protocols`): ``lanrocli.evaluate``. ``info`` is the environment's: the episode's
sentence as text (``instruction_text``), the objects, the correction spoken; the observation holds the
sentence as token ids.

The record is the one ``lanro eval --json`` prints, with the protocol's name and version beside it. The
episodes may run in several processes, or on a Ray cluster (:mod:`lanrocli.evaluation.blocks`), with the
same figures as one process.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import asdict, replace
from typing import Any

from lanrocli.config.curriculum import load_curriculum, packaged_curricula
from lanrocli.envs.env import LanroEnv
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation.adapters import as_policy
from lanrocli.evaluation.blocks import PolicySource, Workers, play
from lanrocli.evaluation.evaluate import EvaluationReport
from lanrocli.evaluation.protocols import PROTOCOL_VERSION, TEST_EPISODES, Protocol, find_protocol, first_seed
from lanrocli.evaluation.quota import CorrectionQuota
from lanrocli.evaluation.splits import CONTROL, DROP, paired_drops
from lanrocli.language import Vocabulary, grammar_vocabulary
from lanrocli.tasks import TASKS


def protocol_env(task: str, chosen: Protocol, vocabulary: Vocabulary | None = None) -> functools.partial[LanroEnv]:
    """What builds the environments of ``chosen`` on ``task``: its packaged curriculum's last stage as
    evaluation sees it, changed by the protocol, with the curriculum's holdout and object slots; the
    sentences encoded by ``vocabulary`` (a trained agent's), else by the grammar's."""
    packaged = packaged_curricula()
    if task not in packaged or task not in TASKS:
        tasks = ", ".join(t for t in TASKS if t in packaged)
        raise ValueError(f"the benchmark plays the tasks with a curriculum of their name ({tasks}), not {task!r}")
    curriculum = load_curriculum(packaged[task])
    stage = curriculum.stages[-1].env.settings().for_evaluation()
    grammar = grammar_vocabulary(curriculum.max_corrections)
    if vocabulary is not None and vocabulary.max_length != grammar.max_length:
        # the sentence's length decides which paraphrases fit, so every policy must read the same one
        raise ValueError(
            f"the benchmark's sentences have {grammar.max_length} words at most, and this agent reads "
            f"{vocabulary.max_length}: score an agent trained on {task}'s curriculum (its max_corrections)"
        )
    return functools.partial(
        LanroEnv,
        curriculum.task,
        stage.replace(**chosen.changes(stage)),
        object_slots=curriculum.max_objects,
        vocabulary=vocabulary or grammar,
        holdout=curriculum.holdout.settings(),
        split=chosen.split,
    )


def _met(quota: CorrectionQuota, report: EvaluationReport, negations: bool) -> bool:
    return quota.met(report, negations)


def _label(policy: Any) -> str:
    return getattr(policy, "name", None) or type(policy).__name__


def evaluate(policy: Any, task: str, protocol: str = "test", **options: Any) -> dict[str, Any]:
    """Score ``policy`` (module docstring), or the policy a ``package.module:function`` spec makes for the
    task, on ``task``'s ``protocol`` (``PROTOCOLS``) and return its record: what ``lanro eval --json``
    prints, and under ``benchmark`` the protocol, its version and the first seed. ``episodes`` plays fewer
    or more (for the correction test: caps them), which the record says (``complete``); ``workers``
    processes share the episodes, or Ray's workers at ``address`` (``auto`` or ``ray://host:port``). With
    several workers the policy must pickle, or come as a spec. A policy that raises or answers with no
    action fails with a :class:`~lanrocli.evaluation.rollout.PolicyError` that names the episode."""
    return score(policy, task, protocol, **options)[1]


def score(
    policy: Any,
    task: str,
    protocol_name: str = "test",
    *,
    episodes: int | None = None,
    workers: int = 1,
    address: str | None = None,
    label: str | None = None,
) -> tuple[EvaluationReport, dict[str, Any]]:
    """:func:`evaluate`'s report and record (``options`` are these keywords), for the command line, which
    prints the report as a table."""
    chosen = find_protocol(protocol_name)
    if episodes is not None and episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    with Workers(workers, address) as pool:
        return _scored(policy, task, chosen, episodes, pool, label)


def _scored(
    policy: Any, task: str, chosen: Protocol, episodes: int | None, pool: Workers, label: str | None
) -> tuple[EvaluationReport, dict[str, Any]]:
    if isinstance(policy, str):
        source = PolicySource(spec=policy, task=task)
        built = source.build()
    else:
        built = as_policy(policy)
        source = pool.source(policy)
    vocabulary = getattr(built, "vocabulary", None)
    make_env = protocol_env(task, chosen, vocabulary if isinstance(vocabulary, Vocabulary) else None)
    env_settings: EnvSettings = make_env.args[1]
    first = first_seed(task, chosen)
    quota = chosen.quota
    if quota is not None:
        quota = replace(quota, episodes=episodes or quota.episodes)
        count = quota.episodes
        enough: Callable[[EvaluationReport], bool] | None = functools.partial(
            _met, quota, negations=env_settings.negations
        )
    else:
        count, enough = episodes or TEST_EPISODES, None
    played = functools.partial(play, pool, source, episodes=count, first=first, instruction=chosen.instruction)
    report = played(make_env, enough=enough)
    record: dict[str, Any] = {
        "benchmark": {
            "protocol": chosen.name,
            "version": PROTOCOL_VERSION,
            "first_seed": first,
            "complete": episodes is None or episodes == (chosen.quota.episodes if chosen.quota else TEST_EPISODES),
        },
        "policy": label or (policy if isinstance(policy, str) else _label(policy)),
        "task": task,
        "env": env_settings.to_dict(),
        "instruction": chosen.instruction.value,
        **report.as_dict(),
    }
    if quota is not None:
        record["quota"] = {**asdict(quota), "negations": quota.negations if env_settings.negations else 0}
        record["quota_met"] = quota.met(report, env_settings.negations)
    if chosen.split is not None:
        record["split"] = chosen.split.value
    if chosen.controlled:
        control = played(functools.partial(make_env, split=None))
        record[CONTROL] = control.as_dict()
        record[DROP] = paired_drops(chosen.split, report.results, control.results)  # type: ignore[arg-type]
    return report, record
