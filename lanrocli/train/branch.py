"""A run that begins where another run's stage ended: a variant of a curriculum's late stages screened
without training its early stages again (``lanro train VARIANT --from RUN``).

The variant must agree with RUN's curriculum on everything but its name and its stages from some stage on;
the first stage in which they differ is where the new run begins. RUN must have finished the stage before
it, which may be its last where the variant adds stages after RUN's end. The new run then holds what RUN
held when that stage ended: the agent, replay buffer, random streams and counters of the checkpoint written
then, and the earlier stages' folders (agents and tests), metrics and TensorBoard events, copied. Training
is deterministic per seed on a given machine, so the new run goes on exactly as a run of the variant from
its first step would, at the cost of its new stages alone. (A copied stage that was RUN's last keeps the
tests of a last stage: its correction test and splits.)
"""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import torch

from lanrocli.config.curriculum import Curriculum, CurriculumError, diff_curricula, load_curriculum
from lanrocli.config.sections import Stage
from lanrocli.train.errors import CheckpointError, RunError
from lanrocli.train.pipeline import CurriculumRun, RunObserver, claim_folder
from lanrocli.train.recovery import clear_leftovers, released_on_error, restore_metrics
from lanrocli.train.runfolder import CONFIG, LAST, METRICS, read_pointer, stage_folder
from lanrocli.train.runstate import RunState
from lanrocli.train.trainer import Trainer
from lanrocli.train.writing import TMP_PREFIX, write_text


def branch_point(source: Curriculum, variant: Curriculum) -> int:
    """The index of the first stage in which ``variant`` differs from ``source``. Raises ``RunError`` where
    they differ anywhere else, from their first stage, or nowhere, or where the variant's scenes need an
    agent of other shapes (more object slots, longer sentences)."""
    alike = variant.model_copy(update={"name": source.name, "stages": source.stages})
    changes = diff_curricula(source, alike, "the run's curriculum", "the curriculum given now")
    if changes:
        raise RunError(
            "--from needs a curriculum that differs from the run's in its stages alone (from some stage on), "
            "as everything else shapes the stages already trained. Change only stages, or start a new run "
            "without --from.\n" + changes
        )
    if (variant.max_objects, variant.max_corrections) != (source.max_objects, source.max_corrections):
        raise RunError(
            f"the curriculum given now has up to {variant.max_objects} objects and {variant.max_corrections} "
            f"corrections per episode, the run's {source.max_objects} and {source.max_corrections}: its agent reads "
            "scenes and sentences of those sizes. Keep them, or start a new run without --from."
        )
    shared = zip(source.stages, variant.stages)
    index = next((i for i, (old, new) in enumerate(shared) if old != new), min(len(source.stages), len(variant.stages)))
    if index == 0:
        raise RunError(
            "the curriculum given now differs from the run's in its first stage: there is nothing to "
            "start from. Start a new run without --from."
        )
    if index >= len(variant.stages):
        raise RunError(
            f"the curriculum given now has no stage after the run's first {index}: there is nothing new "
            "to train. Add or change a stage."
        )
    return index


def branch(
    variant: Curriculum,
    source: Path,
    out: Path,
    device: str | torch.device = "cpu",
    observer: RunObserver | None = None,
) -> CurriculumRun:
    """A new run of ``variant`` in ``out`` (new or empty) that begins where the run in ``source`` ended the
    stage before the first in which their curricula differ."""
    try:
        planned = load_curriculum(source / CONFIG)
    except (CurriculumError, OSError) as error:
        raise RunError(f"--from {source}: no run's curriculum can be read there ({error})") from None
    index = branch_point(planned, variant)
    ended = source / stage_folder(index - 1, planned.stages[index - 1].name)
    try:
        checkpoint = read_pointer(ended / LAST)
        trainer, extra = Trainer.load(checkpoint, device)
    except CheckpointError as error:
        raise RunError(f"--from {source}: its stage {index} has no checkpoint to start from ({error})") from None
    state = RunState.from_dict(extra["run"])
    try:
        if state.finished:
            state = _reopened(state, index, trainer.progress.env_steps, source)
        if state.stage != index:
            raise RunError(
                f"--from {source}: its stage {index} ({planned.stages[index - 1].name}) has not ended yet, and the "
                f"new run would begin where it ends. Resume that run first (lanro train --resume --out {source})."
            )
        lock, notes = claim_folder(out)
        with released_on_error(lock):
            clear_leftovers(out)
            write_text(out / CONFIG, variant.to_yaml())
            if (source / METRICS).is_file():
                shutil.copy2(source / METRICS, out / METRICS)
            restore_metrics(out, checkpoint, extra, notes)
            copies = _copy_stages(planned.stages[:index], source, out)
            run = CurriculumRun(variant, out, trainer, state, observer, lock, notes)
            # The run's own checkpoint first, with its own curriculum: a kill before the copies are in place
            # then resumes this run (testing the copied stages again), never the source's plan.
            run.save_checkpoint()
            for name in copies:
                (out / f"{TMP_PREFIX}{name}").rename(out / name)
    except BaseException:
        trainer.close()
        raise
    run.notes.append(f"began at stage {index + 1} from {ended / LAST} ({state.stage_start:,} environment steps)")
    return run


def _reopened(state: RunState, index: int, env_steps: int, source: Path) -> RunState:
    """The state of a run that completed its curriculum with stage ``index - 1``, as it would have been had
    the curriculum gone on: the variant adds stages after the run's end (a stricter last rule, a larger
    budget, a harder stage), and they begin where it ended, as they would in a run of the variant from its
    first step. A run stopped by a budget (``on_budget: stop``) would stop there in the variant too."""
    if state.stopped_early:
        raise RunError(
            f"--from {source}: that run stopped when the budget of its stage {index} ran out (on_budget: stop), "
            "and the curriculum given now stops there too: change that stage, or start a new run without --from."
        )
    reopened = dataclasses.replace(state, finished=False)
    reopened.begin(index, env_steps)
    return reopened


def _copy_stages(stages: list[Stage], source: Path, out: Path) -> list[str]:
    """The source's TensorBoard events (which drop what follows the branch, as a resumed run's do) and the
    folders of ``stages``, under temporary names; returns their names."""
    for events in source.glob("events.*"):
        shutil.copy2(events, out / events.name)
    names = [stage_folder(i, stage.name) for i, stage in enumerate(stages)]
    for name in names:
        shutil.copytree(source / name, out / f"{TMP_PREFIX}{name}", symlinks=True)
    return names
