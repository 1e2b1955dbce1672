"""sctd simulator: Pinocchio arm, CAN joint bus, task scenes, demonstration generator.

The public names below are imported lazily, so that light modules of this package
(``sctd_sim.demogen``, ``sctd_sim.kinematic``) do not pull in Pinocchio, python-can
and cantools.

Main entry points:

- :class:`Simulation` (``sctd_sim.simulation``): scene + arm, plain-data in and out,
  what the ``sctd sim`` service drives;
- :class:`SimArm` (``sctd_sim.arm``): the arm's full 1 kHz data path
  (controller -> CAN -> drives -> dynamics -> CAN -> controller).

The simulator's figures (``sctd bench sim``) are measured by :mod:`sctd.bench.sim`.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "Simulation": "simulation",
    "start_posture": "simulation",
    "SimArm": "arm",
    "ArmDynamics": "dynamics",
    "CartesianImpedanceController": "controller",
    "ImpedanceGains": "controller",
    "ArmModel": "robot",
    "ArmModelError": "robot",
    "load_arm_model": "robot",
    "inverse_kinematics": "robot",
    "FaultConfig": "canbus",
    "FaultInjectingBus": "canbus",
    "TaskScene": "scenes",
    "make_scene": "scenes",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'sctd_sim' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{module}", __name__), name)
