"""The simulated user: a person who knows the task, not the skill.

:class:`SimulatedUser` combines the task file's intent (:mod:`.intent`), a model of the input
device it learns from the robot's response (:mod:`.device`) and human limits
(:mod:`.human`). ``sctd eval`` and ``sctd demo`` drive skills with it; the Zenoh client
is :mod:`sctd_services.simulated_user`.
"""

from .agent import SimulatedUser, twist_between
from .device import DelayedDeviceModel, DeviceModel
from .human import DEFAULT_MODEL, DEFAULT_PROFILE, PROFILES, USER_MODELS, HumanProfile, UserModel
from .intent import Desire, Observation, TaskIntent
from .setuser import SetUser

__all__ = ["DEFAULT_MODEL", "DEFAULT_PROFILE", "PROFILES", "USER_MODELS", "DelayedDeviceModel", "Desire",
           "DeviceModel", "HumanProfile", "Observation", "SetUser", "SimulatedUser", "TaskIntent",
           "UserModel", "twist_between"]
