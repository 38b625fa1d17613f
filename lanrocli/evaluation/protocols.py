"""The benchmark's protocols: fixed episodes on which any policy is scored, the same in every lab.

Each protocol is a way of playing a task's packaged curriculum's last stage, as evaluation sees it
(neutral starts), with the curriculum's holdout: its held-out test, its correction test, the language
check (a blank sentence, another object's sentence) and each generalisation split. Its episodes come
from a seed stream of the benchmark's own (:func:`~lanrocli.core.seeds.benchmark_seed`), apart from any
run's training, evaluation and tests, so a lanro agent scored here meets episodes nothing was selected on.

:data:`PROTOCOL_VERSION` names the episodes. A change to anything that makes them (the curricula's last
stages, the scenes, the instructor, the seeds) changes the numbers, and must change the version, so that
two records with the same version were measured on the same episodes; ``tests/evaluation/test_protocols.py``
holds the first episodes of every protocol fixed and fails until the version moves with them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from lanrocli.core.choices import Instruction, Split
from lanrocli.core.seeds import benchmark_seed
from lanrocli.envs.settings import EnvSettings
from lanrocli.evaluation.quota import CORRECTION_QUOTA, CorrectionQuota, correction_changes
from lanrocli.evaluation.splits import CONTROLLED, split_changes

PROTOCOL_VERSION = 1
"""The version of every protocol's episodes; a record carries it."""

TEST_EPISODES = 500
"""Episodes of every protocol but the correction test, which runs to its quota: a rate's 95% interval
within about 4.5 points either side."""


@dataclass(frozen=True)
class Protocol:
    """How a protocol plays the last stage: its changes to the stage's settings, the sentence the policy
    reads, the split whose episodes it plays, and whether it runs until a quota of spoken corrections."""

    name: str
    description: str
    changes: Callable[[EnvSettings], dict[str, Any]]
    instruction: Instruction = Instruction.TRUE
    split: Split | None = None
    quota: CorrectionQuota | None = None

    @property
    def controlled(self) -> bool:
        """Whether the record carries a control: the same seeds with nothing held out."""
        return self.split in CONTROLLED

    @property
    def index(self) -> int:
        """The protocol's place in :data:`PROTOCOLS`, which its seeds carry: new protocols are appended."""
        return list(PROTOCOLS).index(self.name)


def _unchanged(_: EnvSettings) -> dict[str, Any]:
    return {}


def _plain(_: EnvSettings) -> dict[str, Any]:
    return {"correction_rate": 0.0}


def _split(split: Split, description: str) -> Protocol:
    return Protocol(split.value, description, split_changes(split), split=split)


PROTOCOLS: dict[str, Protocol] = {
    protocol.name: protocol
    for protocol in (
        Protocol("test", "the last stage as it is: the held-out test", _unchanged),
        Protocol(
            "correction_test",
            "every episode a correction episode, half the spoken corrections negations, until 300 corrections and "
            "150 negations were spoken (3000 episodes at most)",
            correction_changes,
            quota=CORRECTION_QUOTA,
        ),
        Protocol(
            "blank_instruction",
            "no correction episodes, and the policy reads an empty sentence",
            _plain,
            Instruction.BLANK,
        ),
        Protocol(
            "other_instruction",
            "no correction episodes, and the policy reads a sentence naming another object: success is the task on it",
            _plain,
            Instruction.OTHER,
        ),
        _split(Split.PAIRS, "the goal a colour-shape pair never on the table in training"),
        _split(Split.CORRECTION_WORDS, "every correction with a shape word never heard in a correction"),
        _split(Split.LATE_CORRECTIONS, "corrections later after the mistake than any in training"),
        _split(Split.COMMON_GROUND, "common-ground corrections after a rare colour word never heard"),
        _split(Split.PARAPHRASE, "corrections phrased as the grammar never phrases them, some verbs never heard"),
    )
}
"""Every protocol, by name, in the order their seeds were given."""


def find_protocol(name: str) -> Protocol:
    """The protocol named ``name``, or a ValueError that lists them."""
    if name not in PROTOCOLS:
        raise ValueError(f"unknown protocol {name!r}: choose one of {', '.join(PROTOCOLS)}")
    return PROTOCOLS[name]


def first_seed(task: str, chosen: Protocol) -> int:
    """The seed of the protocol's episode 0 for ``task``; episode i is reset with this plus i."""
    return benchmark_seed(task, chosen.index)
