"""Any policy in a shape the rollout drives (:mod:`lanrocli.evaluation.rollout`), tried in this order: an
object with ``act_batch(observations) -> (actions, attention or None)`` (lanro's agents), one with
``act(observation, info)`` and optionally ``reset(seed)`` (lanro's scripted policies), a stable-baselines3
model or policy (anything with ``predict(observation, deterministic=True)``), or a plain function
``f(observation, info) -> action``; and the factories that make one for a task, named on the command line."""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


class PredictPolicy:
    """A stable-baselines3 model (or anything with its ``predict``) as a batch policy, acting deterministically."""

    def __init__(self, model: Any) -> None:
        self.model = model

    def act_batch(self, observations: dict[str, np.ndarray]) -> tuple[np.ndarray, None]:
        actions, _ = self.model.predict(observations, deterministic=True)
        return np.asarray(actions), None


class FunctionPolicy:
    """A function ``f(observation, info) -> action`` as a policy without state."""

    def __init__(self, function: Callable[[dict[str, np.ndarray], dict[str, Any]], Any]) -> None:
        self.function = function

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> Any:
        return self.function(observation, info)


def as_policy(policy: Any) -> Any:
    """``policy`` in a shape the rollout drives (module docstring), or a TypeError that says what is missing."""
    if hasattr(policy, "act_batch") or hasattr(policy, "act"):
        return policy
    if hasattr(policy, "predict"):
        return PredictPolicy(policy)
    if callable(policy):
        return FunctionPolicy(policy)
    raise TypeError(
        f"{policy!r} is not a policy: give a function f(observation, info) -> action, an object with "
        "act(observation, info), or a stable-baselines3 model"
    )


def load_factory(spec: str) -> Callable[[str], Any]:
    """The function ``spec`` names, ``package.module:function`` or ``path/to/file.py:function``, which
    makes a policy for a task's name; a ValueError that says what went wrong."""
    module_name, _, attribute = spec.rpartition(":")
    if not module_name or not attribute:
        raise ValueError(f"{spec!r} names no function: write package.module:make_policy or file.py:make_policy")
    try:
        if module_name.endswith(".py"):
            path = Path(module_name).resolve()
            if not path.is_file():
                raise ValueError(f"{spec!r}: there is no file {path}")
            loader = importlib.util.spec_from_file_location(path.stem, path)
            assert loader is not None and loader.loader is not None
            module = importlib.util.module_from_spec(loader)
            sys.modules[loader.name] = module  # as an import would: dataclasses and pickles look it up there
            loader.loader.exec_module(module)
        else:
            if "" not in sys.path:  # a module beside the command line's folder, as `python -m` finds it
                sys.path.insert(0, "")
            module = importlib.import_module(module_name)
    except ValueError:
        raise
    except Exception as error:
        raise ValueError(f"cannot import {module_name!r} for {spec!r}: {type(error).__name__}: {error}") from error
    factory = getattr(module, attribute, None)
    if not callable(factory):
        raise ValueError(f"{spec!r}: {module_name} has no function {attribute!r}")
    return factory
