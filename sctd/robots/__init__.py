"""Robots as plug-ins: the driver contract and the registry of drivers.

A robot is a :class:`RobotDriver` (connect, stream readings, take targets, report
faults, recover, close), found by name through :func:`get_driver`: the built-in drivers
(``sim``, the Pinocchio simulator; ``kinematic``, the stand-in; ``franky``, a Franka FR3
through libfranka's protocol) and any a package registers under the entry-point group
``sctd.robots``, as python-can registers its interfaces. ``sctd robot NAME`` serves any
of them on the wire (:mod:`sctd_services.robots`); docs/robots.md says how to write one.
"""

from .contract import Reading, RobotDriver, RobotError, RobotFault
from .registry import GROUP, driver_names, get_driver

__all__ = ["GROUP", "Reading", "RobotDriver", "RobotError", "RobotFault", "driver_names", "get_driver"]
