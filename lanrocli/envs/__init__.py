"""Tasks, scenes, the synthetic instructor and the gymnasium environment that ties them to the simulation.

The environment, and with it pybullet, is imported from :mod:`lanrocli.envs.env`; this package itself loads
nothing, so settings, scenes and evaluation reports are read without starting a physics engine.
"""
