"""The named choices every layer shares (tasks, modes, kinds and forms of correction, splits), the
registries of what may be extended, the seeds of each kind of episode, the reward and interval statistics.
Imports nothing of lanro's."""
