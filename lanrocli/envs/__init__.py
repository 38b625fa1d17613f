"""Tasks, scenes, the synthetic instructor and the gymnasium environment that ties them to the simulation."""

from gymnasium.envs.registration import register, registry

from lanrocli.envs.env import ARM_SIZE, OBJECT_SIZE, LanroEnv, observation_size
from lanrocli.envs.instructor import Correction, Instructor, InstructorSettings, Kind
from lanrocli.envs.scene import Mode, Scene

ENV_IDS = {"reach": "lanro/Reach-v0", "push": "lanro/Push-v0", "grasp": "lanro/Grasp-v0", "lift": "lanro/Lift-v0"}

for _task, _env_id in ENV_IDS.items():
    if _env_id not in registry:
        register(id=_env_id, entry_point="lanrocli.envs.env:LanroEnv", kwargs={"task": _task})

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
