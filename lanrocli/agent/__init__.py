"""The learning agent: sentence encoder, actor and critics, SAC updates, the replay buffer and hindsight
language relabelling. Knows nothing of configuration files, the terminal or where checkpoints live.

Import from the modules themselves: this package loads nothing, so the agent's settings
(:mod:`lanrocli.agent.settings`) are read, and a curriculum checked, without starting torch.
"""
