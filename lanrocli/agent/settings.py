"""The agent's and the replay buffer's settings: plain dataclasses, so that a curriculum is checked (``lanro
check``) without loading torch, which the agent itself needs."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

from lanrocli.core.choices import ActingAttention

UPDATE_METRICS = (
    "critic_loss",
    "actor_loss",
    "alpha_loss",
    "grounding_loss",
    "alpha",
    "q_mean",
    "target_q_mean",
    "entropy",
)
"""The figures each update of the agent reports, in its order; ``metrics.csv`` has a column for each."""

CRITIC_METRICS = ("critic_loss", "alpha", "q_mean", "target_q_mean")
"""The figures an update that trains the critic alone reports (``SACSettings.actor_every``), in its order; the
others are averaged over the updates that train the actor."""


@dataclass(frozen=True)
class SACSettings:
    """Every number of the agent. Defaults are the paper's (its appendix, table of hyperparameters) where it
    gives one, else those of the SAC baseline it builds on."""

    batch_size: int = 256
    actor_lr: float = 1e-3
    critic_lr: float = 1e-3
    alpha_lr: float = 1e-3
    alpha: float = 0.2
    """Entropy temperature; the initial value when ``autotune_alpha``."""
    autotune_alpha: bool = True
    target_entropy: float | None = None
    """Entropy the temperature tuning aims at; ``None`` means -action_dim."""
    gamma: float = 0.98
    polyak: float = 0.95
    """target <- polyak * target + (1 - polyak) * online, after every update."""
    critics: int = 1
    """1 as in the paper; 2 for clipped double Q (the target takes the smaller)."""
    clip_target: bool = True
    """Clip Bellman targets to the returns eq. 1 allows, [-1 / (1 - gamma), 0], as HER does. Without it a
    critic extrapolates to positive values that no episode can earn, the actor chases them, and the
    values diverge."""
    embedding_size: int = 32
    language_size: int = 32
    """GRU hidden size: the length of the sentence summary."""
    obs_size: int = 128
    """Width of the observation layer, and of the attention's keys and queries (objects)."""
    hidden_size: int = 256
    hidden_layers: int = 1
    architecture: Literal["flat", "objects"] = "flat"
    """``flat``: the observation through one layer, joined with the sentence summary (the paper's baseline);
    ``objects``: attention of the sentence summary over the objects picks the named one, and the observation
    layer reads the arm's features and that object's. Needs the observation's layout (:class:`ObjectLayout`)."""
    grounding: float = 1.0
    """Weight of an auxiliary loss for ``architecture: objects``: the cross-entropy between each reader's
    attention over the objects and the object a relabelled sentence singles out (which the buffer knows,
    since it chose the sentence for that object). It teaches actor and critic which object a sentence
    names directly, rather than only through the small differences it makes to Bellman targets. 0 turns
    it off."""
    sentence_in_trunk: bool = True
    """Whether the layers that choose the action (and judge it) read the sentence summary beside the
    observation. With ``architecture: objects`` and ``False`` the sentence acts through the attention
    alone: it picks the object, and the motor layers see the arm and that object, so a negation or an
    unfamiliar correction cannot disturb how the arm moves, only what it moves to."""
    acting_attention: str = ActingAttention.SOFT.value
    """How a deterministic action (evaluations, and so promotion; tests; ``lanro play``) reads the scene with
    ``architecture: objects``: ``soft``, the attention-weighted mix of the objects that training reads;
    ``argmax``, the one object the attention weighs most. A split attention (an ambiguous instruction, what a
    negation leaves on the object it names) mixes objects into a place where none is, and the arm heads
    there; committing to one object acts on it, and if it is the wrong one, a correction follows. Training's
    exploring actions and updates, and the attention the tests report, stay soft, so an agent trained either
    way can be measured the other (``lanro eval --acting-attention``)."""
    share_encoder: bool = False
    """One sentence encoder for actor and critic, trained by the critic's loss only."""
    actor_every: int = 1
    """The actor and the temperature learn in every ``actor_every``-th update, the critic in each (the
    delayed policy updates of TD3 and CrossQ). An update that leaves the actor alone skips its forward and
    backward pass and, with an encoder of its own, its reading's backward pass."""
    max_grad_norm: float | None = None
    """Clip each network's gradient to this norm; ``None`` leaves gradients as they are."""
    log_std_min: float = -20.0
    log_std_max: float = 2.0
    obs_clip: float = 5.0
    """Normalised observations are clipped to +-obs_clip."""
    obs_var_eps: float = 1e-4
    """Added to the observation variance: a feature that barely varies is scaled by at most 100."""
    compile: bool = False
    """Compile the update's losses with ``torch.compile`` (:func:`~lanrocli.agent.losses.compiled_losses`): the
    same arithmetic in fewer, fused operations, paid for by a compilation when the agent first updates. On CPU
    torch builds its kernels with a C++ compiler; where none works, the update stays eager and says so. Fused
    sums round differently in the last bits, so a run is reproducible with the setting it ran with."""

    ARCHITECTURE: ClassVar[tuple[str, ...]] = (
        "critics",
        "embedding_size",
        "language_size",
        "obs_size",
        "hidden_size",
        "hidden_layers",
        "architecture",
        "share_encoder",
        "autotune_alpha",
        "sentence_in_trunk",
    )
    """The settings that shape the networks and the optimiser's state: a saved agent loads only into one
    that agrees on them."""

    def __post_init__(self) -> None:
        if self.architecture not in ("flat", "objects"):
            raise ValueError(f"architecture must be 'flat' or 'objects', got {self.architecture!r}")
        if self.critics not in (1, 2):
            raise ValueError(f"critics must be 1 or 2, got {self.critics}")
        if self.alpha <= 0.0:
            raise ValueError(f"alpha must be positive, got {self.alpha}")
        if not 0.0 <= self.polyak <= 1.0 or not 0.0 <= self.gamma < 1.0:
            raise ValueError("gamma must lie in [0, 1) and polyak in [0, 1]")
        if not self.sentence_in_trunk and self.architecture != "objects":
            raise ValueError(
                "sentence_in_trunk: false needs architecture 'objects': a flat network reads the sentence only there"
            )
        if self.acting_attention not in tuple(ActingAttention):
            choices = " or ".join(repr(a.value) for a in ActingAttention)
            raise ValueError(f"acting_attention must be {choices}, got {self.acting_attention!r}")
        if self.acting_attention != ActingAttention.SOFT and self.architecture != "objects":
            raise ValueError("acting_attention: argmax needs architecture 'objects': a flat network has no attention")
        if self.grounding < 0.0:
            raise ValueError(f"grounding must not be negative, got {self.grounding}")
        if self.actor_every < 1:
            raise ValueError(f"actor_every must be a positive number of updates, got {self.actor_every}")
        if self.batch_size < 1 or self.hidden_layers < 0:
            raise ValueError("batch_size must be positive and hidden_layers not negative")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SACSettings:
        """Settings from plain data, refusing names these settings do not have."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown SAC settings: {', '.join(unknown)}")
        return cls(**data)


@dataclass(frozen=True)
class BufferSettings:
    """How many transitions the replay buffer keeps and how its batches are drawn and relabelled.

    Defaults are the paper's buffer size and those of the hindsight relabelling it builds on."""

    size: int = 1_000_000
    """Transitions kept; the oldest whole episodes make room for new ones."""
    relabel_ratio: float = 0.8
    """Probability that a sampled transition is relabelled, where its episode achieved the task on some
    object at that step or later."""
    relabel_corrections: bool = True
    correction_share: float = 0.5
    """With ``relabel_corrections``, the share of relabelled sentences that are corrections."""
    hindsight_share: float = 0.5
    """Share of each batch drawn from the transitions that relabelling can turn into successes (their episode
    achieves the task on some object at that step or later); the rest is drawn uniformly. Sparse tasks need
    it: random arms touch objects rarely, so few stored transitions can be relabelled at all, and uniform
    batches hold almost no success (docs/lab/lab-notebook.md has the figures)."""
    relabel_negations: bool = False
    """Relabelled corrections may be negations in every stage, not only in those whose instructor speaks
    them: an agent then meets "not the ..." from its first stage on."""
    fresh_targets: bool = False
    """Relabel only to objects the task did not already hold for before the step: a transition relabelled to
    an object the arm had already pushed or was touching is won whatever its action, and teaches nothing."""
    ground_real: bool = False
    """Teach the attention on stored transitions too: wherever a transition's sentence singles out its
    goal (every step of a plain episode, the steps after a spoken correction), the goal is its label. A
    transition whose correction is still pending is never labelled."""

    def __post_init__(self) -> None:
        if not 1 <= self.size < 2**31:
            raise ValueError(f"size must be a positive number of transitions below 2**31, got {self.size}")
        for name in ("relabel_ratio", "correction_share", "hindsight_share"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {getattr(self, name)}")

    @property
    def corrected_share(self) -> float:
        """The share of relabelled sentences that are corrections: ``correction_share``, or none without
        ``relabel_corrections``."""
        return self.correction_share if self.relabel_corrections else 0.0
