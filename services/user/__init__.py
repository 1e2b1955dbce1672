"""The simulated user: a person who knows the task, not the skill.

:class:`SimulatedUser` combines the task file's intent (:mod:`.intent`), a model of the input
device it learns from the robot's response (:mod:`.device`) and human limits
(:mod:`.human`). ``sctd eval`` and ``sctd demo`` drive skills with it; the Zenoh client
is :mod:`sctd_services.simulated_user`.
"""

from .agent import SimulatedUser, twist_between
from .device import DeviceModel
from .human import DEFAULT_PROFILE, PROFILES, HumanProfile
from .intent import Desire, Observation, TaskIntent
from .setuser import SetUser

__all__ = ["DEFAULT_PROFILE", "PROFILES", "Desire", "DeviceModel", "HumanProfile", "Observation",
           "SetUser", "SimulatedUser", "TaskIntent", "twist_between"]
