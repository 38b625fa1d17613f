"""Training: vectorised collection, the stage loop, evaluation, checkpoints and resume."""

from lanrocli.train.checkpoint import CheckpointError
from lanrocli.train.trainer import AgentPolicy, Trainer, TrainSettings, pick_device

__all__ = ["AgentPolicy", "CheckpointError", "TrainSettings", "Trainer", "pick_device"]
