"""A run's TensorBoard events, written beside ``metrics.csv`` when the optional ``tensorboard`` package is
installed (``pip install -e '.[tensorboard]'``; without it a run writes none and says nothing):

- ``train/``: the learner's figures as of its last update (its losses, alpha, entropy and Q, the agent's
  columns of ``metrics.csv``), ``train_success`` (the stochastic policy's recent training episodes) and
  ``env_steps_per_second`` of collecting and learning, ``TRAIN_POINTS`` times between two evaluations
  (every 2,000 steps for ``eval.every: 10000``);
- ``eval/``: each evaluation's figures, by their ``metrics.csv`` names (``eval/success``, ...);
- ``test/``: each stage's test figures at the step the stage ended, per agent (``test/last/success``,
  ``test/best/corrected_success``) and, for the last stage, the language check (``test/language/blank/success``),
  the correction test (``test/correction_test/last/corrected_success_negation``) and the generalisation splits
  of a curriculum's holdout (``test/splits/pairs/last/success``);
- HParams: the resolved curriculum, by the key paths ``--set`` uses, with ``HPARAM_METRICS`` beside it, so
  that runs of a sweep compare setting against result.

Only the figures are TensorBoard's: what a run decides and reports comes from ``metrics.csv`` and
``test.json``. This module loads torch's writer only when a run opens it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from lanrocli.config.curriculum import Curriculum
from lanrocli.config.overrides import flatten
from lanrocli.core.registry import Live
from lanrocli.evaluation.metrics import METRIC_NAMES

TRAIN_POINTS = 5
"""Points of the ``train/`` group per evaluation interval: a curve between evaluations, not one per step."""
EVALUATION_FIGURES: Live[str] = Live(lambda: (*METRIC_NAMES, "mean_return", "mean_length", "rule_value"))
"""The columns of a ``metrics.csv`` row that describe the evaluation (the others are ``train/``'s)."""
HPARAM_METRICS = ("test/last/success", "test/last/corrected_success", "eval/success")
"""The figures the HParams dashboard shows beside each run's settings."""


class TensorBoard:
    """The events of one run folder; every method does nothing where ``tensorboard`` is not installed."""

    def __init__(self, writer: Any, train_every: int, env_steps: int) -> None:
        self._writer = writer
        self._train_every = train_every
        self._since = (env_steps, time.perf_counter())

    @classmethod
    def open(cls, out: Path, env_steps: int, eval_every: int) -> TensorBoard:
        """The events of the run in ``out``, which continues from ``env_steps``: anything a killed run
        wrote after that step is dropped (``purge_step``), and what it wrote up to it is kept, as the
        checkpoint it resumes from was written then."""
        train_every = max(1, eval_every // TRAIN_POINTS)
        try:
            # Here and not at the top: the writer comes with torch, which readers of a run folder do not need.
            from torch.utils.tensorboard import SummaryWriter
        except ImportError:
            return cls(None, train_every, env_steps)
        return cls(SummaryWriter(str(out), purge_step=env_steps + 1 if env_steps else None), train_every, env_steps)

    def hyperparameters(self, curriculum: Curriculum) -> None:
        """The resolved curriculum, written once as the run starts: every value by its key path
        (``stages[0].env.objects``), lists item by item; a value TensorBoard cannot show, such as a
        default left empty, as its JSON text."""
        if self._writer is None:
            return
        from torch.utils.tensorboard.summary import hparams

        values = {
            key: value if isinstance(value, (bool, int, float, str)) else json.dumps(value)
            for key, value in flatten(curriculum.model_dump(mode="json")).items()
        }
        for summary in hparams(values, dict.fromkeys(HPARAM_METRICS, 0.0)):
            self._writer.file_writer.add_summary(summary)
        self._writer.flush()

    def train(self, env_steps: int, figures: Mapping[str, float | None]) -> None:
        """The learner's ``figures`` and the steps per second since the last point (or ``mark``), when
        ``env_steps`` has passed the next point; called after every step."""
        steps, clock = self._since
        if self._writer is None or env_steps // self._train_every == steps // self._train_every:
            return
        now = time.perf_counter()
        self._scalar("train/env_steps_per_second", (env_steps - steps) / max(now - clock, 1e-9), env_steps)
        for name, value in figures.items():
            self._scalar(f"train/{name}", value, env_steps)
        self._since = (env_steps, now)

    def mark(self, env_steps: int) -> None:
        """Restart the clock of the steps per second: the evaluating, testing and checkpointing just done are
        no part of collecting and learning."""
        self._since = (env_steps, time.perf_counter())

    def evaluation(self, row: Mapping[str, Any]) -> None:
        """An evaluation's figures, from its ``metrics.csv`` row."""
        for name in EVALUATION_FIGURES:
            self._scalar(f"eval/{name}", row.get(name), row["env_steps"])
        self._flush()

    def test(self, env_steps: int, figures: Mapping[str, Mapping[str, float | int | None]]) -> None:
        """A stage's test figures (``EvaluationReport.metrics``) by what was measured (``last``,
        ``language/blank``, ``correction_test/best``), at the step the stage ended."""
        for measured, metrics in figures.items():
            for name, value in metrics.items():
                self._scalar(f"test/{measured}/{name}", value, env_steps)
        self._flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()

    def _scalar(self, tag: str, value: Any, step: int) -> None:
        """Numbers only: a figure with nothing to measure is None (or empty in a ``metrics.csv`` row)."""
        if self._writer is not None and isinstance(value, (int, float)) and not isinstance(value, bool):
            self._writer.add_scalar(tag, value, step)

    def _flush(self) -> None:
        if self._writer is not None:
            self._writer.flush()
