"""lanro: language-conditioned reinforcement learning for a simulated Panda arm that recovers from corrections."""

from importlib.metadata import PackageNotFoundError, version

from lanrocli.envs.registration import register_envs

try:
    __version__ = version("lanro")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0"

register_envs()
