"""The replay buffer: whole episodes in a ring, sampled in batches with hindsight language relabelling."""
