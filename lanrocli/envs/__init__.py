"""Tasks, scenes, the synthetic instructor and the gymnasium environment that ties them to the simulation."""

from lanrocli.envs.env import ARM_SIZE, OBJECT_SIZE, LanroEnv, observation_size
from lanrocli.envs.instructor import Correction, Instructor, InstructorSettings, Kind
from lanrocli.envs.scene import Mode, Scene
from lanrocli.registration import ENV_IDS

__all__ = [
    "ARM_SIZE",
    "ENV_IDS",
    "Correction",
    "Instructor",
    "InstructorSettings",
    "Kind",
    "LanroEnv",
    "Mode",
    "OBJECT_SIZE",
    "Scene",
    "observation_size",
]
