"""The robot drivers: the built-in ones and any a package registers under the entry-point
group ``sctd.robots`` (as python-can registers its interfaces under ``can.interface``).

An entry point names a :class:`~sctd.robots.contract.RobotDriver` subclass::

    [project.entry-points."sctd.robots"]
    myarm = "mypackage.sctd_driver:MyArm"

A driver's module is imported only when it is asked for (franky's, for instance, needs
``pip install 'sctd[franky]'``). A built-in name wins over an entry point of the same
name.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points

from .contract import RobotDriver, RobotError

GROUP = "sctd.robots"
BUILTIN = {
    "sim": "sctd_sim.drivers:SimDriver",
    "kinematic": "sctd_sim.drivers:KinematicDriver",
    "franky": "sctd_services.robots.franky:FrankyDriver",
}


def _load(target: str) -> type[RobotDriver]:
    module, _, attr = target.partition(":")
    cls = getattr(importlib.import_module(module), attr)
    if not (isinstance(cls, type) and issubclass(cls, RobotDriver)):
        raise RobotError(f"{target}: not an sctd robot driver (a subclass of RobotDriver)")
    return cls


def driver_names() -> list[str]:
    """Every driver's name: the built-in ones first, then the registered ones."""
    extra = sorted(ep.name for ep in entry_points(group=GROUP) if ep.name not in BUILTIN)
    return [*BUILTIN, *extra]


def get_driver(name: str) -> type[RobotDriver]:
    """The driver class ``name`` (built-in or registered). RobotError naming the known
    ones for an unknown name; ModuleNotFoundError (with the library's name) when the
    driver's library is not installed."""
    if name in BUILTIN:
        target = BUILTIN[name]
    else:
        found = [ep.value for ep in entry_points(group=GROUP) if ep.name == name]
        if not found:
            raise RobotError(f"unknown robot driver {name!r}; known: {', '.join(driver_names())}")
        target = found[0]
    try:
        return _load(target)
    except ModuleNotFoundError:
        raise
    except (ImportError, AttributeError) as e:  # a broken plug-in: say which, keep the others
        raise RobotError(f"robot driver {name!r} ({target}) does not load: {e}") from e
