"""The errors of a run folder, apart from the modules that raise them, so that every layer of ``train/`` can
name them without importing the others."""

from __future__ import annotations


class CheckpointError(RuntimeError):
    """A checkpoint is missing, incomplete, damaged, or not plain data."""


class RunError(RuntimeError):
    """A run cannot start or resume as asked (the folder is in use, the curriculum changed, ...)."""
