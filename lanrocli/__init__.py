"""lanro: language-conditioned reinforcement learning for a simulated Panda arm that recovers from corrections.

``lanrocli.evaluate(policy, task, protocol)`` scores any policy on the benchmark's protocols
(:func:`lanrocli.evaluation.benchmark.evaluate`); it is imported when first used, so ``import lanrocli``
stays light.
"""

from importlib.metadata import PackageNotFoundError, version
from typing import Any

from lanrocli.envs.registration import register_envs

try:
    __version__ = version("lanro")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0"

register_envs()


def __getattr__(name: str) -> Any:
    if name == "evaluate":
        from lanrocli.evaluation.benchmark import evaluate

        return evaluate
    raise AttributeError(f"module 'lanrocli' has no attribute {name!r}")
