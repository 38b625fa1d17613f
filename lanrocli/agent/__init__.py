"""The learning agent: sentence encoder, actor and critics, SAC updates, the replay buffer and hindsight
language relabelling. Knows nothing of configuration files, the terminal or where checkpoints live."""

from lanrocli.agent.buffer import FAILURE_REWARD, SUCCESS_REWARD, Batch, BufferSettings, EpisodeData, ReplayBuffer
from lanrocli.agent.networks import Actor, Critic, LanguageEncoder, ObjectLayout
from lanrocli.agent.normalizer import RunningNormalizer
from lanrocli.agent.relabel import SentencePool, TargetPhrases, sentence_pool, target_phrases
from lanrocli.agent.sac import SACAgent, SACSettings

__all__ = [
    "FAILURE_REWARD",
    "SUCCESS_REWARD",
    "Actor",
    "Batch",
    "BufferSettings",
    "Critic",
    "EpisodeData",
    "LanguageEncoder",
    "ObjectLayout",
    "ReplayBuffer",
    "RunningNormalizer",
    "SACAgent",
    "SACSettings",
    "SentencePool",
    "TargetPhrases",
    "sentence_pool",
    "target_phrases",
]
