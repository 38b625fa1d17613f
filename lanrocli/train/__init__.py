"""Training: vectorised collection, the stage loop, evaluation, checkpoints and resume.

Import from the modules themselves: this package loads nothing, so reading a run folder (plotting, say)
starts neither torch nor pybullet.
"""
