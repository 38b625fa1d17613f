"""A trained agent as evaluation and tests ask a policy to act: deterministic, and by the batch."""

from __future__ import annotations

from typing import Any

import numpy as np

from lanrocli.agent.sac import SACAgent
from lanrocli.language import Vocabulary


class AgentPolicy:
    """The agent's deterministic policy in the scripted-policy interface, for evaluation, with the
    vocabulary it reads: the environments it acts in must encode their sentences with it."""

    def __init__(self, agent: SACAgent, vocabulary: Vocabulary) -> None:
        self.agent = agent
        self.vocabulary = vocabulary

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        return self.agent.act(observation, deterministic=True)

    def act_batch(self, observations: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray | None]:
        """Actions and attention for several episodes' observations at once (``rollout.BatchPolicy``):
        evaluation reads the attention to tell how much of it lies on the goal."""
        return self.agent.act_and_attend(observations)
