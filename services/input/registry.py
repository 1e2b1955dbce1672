"""The input backends: the built-in ones and any a package registers under the entry
point group ``sctd.input`` (as python-can registers its buses under ``can.interface``).

An entry point names a :class:`~sctd_services.input.device.Backend` subclass::

    [project.entry-points."sctd.input"]
    mydevice = "mypackage.sctd_backend:MyDevice"

A built-in name wins over an entry point of the same name.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points

from .device import Backend, InputError

GROUP = "sctd.input"
BUILTIN = {
    "gamepad": "sctd_services.input.gamepad:Gamepad",
    "spacemouse": "sctd_services.input.spacemouse:SpaceMouse",
    "emg": "sctd_services.input.emg:Emg",
    "keyboard": "sctd_services.input.keyboard:Keyboard",
}


def _load(target: str) -> type[Backend]:
    module, _, attr = target.partition(":")
    cls = getattr(importlib.import_module(module), attr)
    if not (isinstance(cls, type) and issubclass(cls, Backend)):
        raise InputError(f"{target}: not an sctd input backend (a subclass of Backend)")
    return cls


def backend_names() -> list[str]:
    """Every backend's name: the built-in ones first, then the registered ones."""
    extra = sorted(ep.name for ep in entry_points(group=GROUP) if ep.name not in BUILTIN)
    return [*BUILTIN, *extra]


def get_backend(name: str) -> Backend:
    """The backend ``name`` (built-in or registered); InputError naming the known ones."""
    if name in BUILTIN:
        try:
            return _load(BUILTIN[name])()
        except (ImportError, AttributeError) as e:  # a bug: say so, keep the others
            raise InputError(f"backend {name!r} ({BUILTIN[name]}) does not load: {e}") from e
    for ep in entry_points(group=GROUP):
        if ep.name == name:
            try:
                return _load(ep.value)()
            except (ImportError, AttributeError) as e:
                raise InputError(f"backend {name!r} (entry point {ep.value}): {e}") from e
    raise InputError(f"unknown backend {name!r}; known: {', '.join(backend_names())}")
