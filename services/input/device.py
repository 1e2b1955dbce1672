"""What every input backend provides: devices that report their axes and buttons, and a
backend that lists and opens them (``docs/input.md``).

A backend wraps one device library (SDL2, hidapi, BrainFlow, the terminal). It never
starts network discovery and imports its library only when asked, so ``sctd input
--list`` works with any subset of the libraries installed.
"""

from __future__ import annotations

import argparse
from abc import ABC, abstractmethod
from dataclasses import dataclass


class InputError(RuntimeError):
    """A device or its configuration cannot be used (bad selector, bad file, library
    error): the message names what and where."""


@dataclass(frozen=True)
class Reading:
    """A device's state at ``stamp`` (Unix time, s): its axes in [-1, 1] and its
    buttons (0/1) by the device's own numbering, before the mapping file."""

    axes: tuple[float, ...]
    buttons: tuple[int, ...] = ()
    stamp: float = 0.0


@dataclass(frozen=True)
class DeviceInfo:
    """One device a backend sees now: what ``--device`` matches (its index or a part of
    its name) and what ``--list`` prints."""

    index: int
    name: str
    detail: str = ""


class InputDevice(ABC):
    """An open device. :meth:`read` is called at the bridge's rate from one thread.

    Attributes
    ----------
    name : str
        The device's name as its library reports it.
    axes, buttons : int
        How many raw axes and buttons a :class:`Reading` carries.
    """

    name: str = ""
    axes: int = 0
    buttons: int = 0

    @abstractmethod
    def read(self) -> Reading | None:
        """The device's newest state, without blocking; None while it is disconnected
        (the bridge then publishes zero; a backend with hot-plug reconnects by itself on
        a later call)."""

    def close(self) -> None:  # noqa: B027  (a device without resources needs none)
        """Release the device (idempotent)."""

    def __enter__(self) -> InputDevice:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Backend(ABC):
    """One kind of input device.

    Attributes
    ----------
    name : str
        ``sctd input NAME``.
    help : str
        One line for ``--list`` and ``--help``.
    library : str
        The Python distribution it needs (what ``--list`` says is missing).
    extra : str
        The sctd extra that installs it.
    default_map : str
        The shipped mapping file's name in ``sctd_services/input/maps`` ("" for the
        identity mapping).
    device_axes, device_buttons : int or None
        How many axes and buttons its devices number (0 to n - 1), at most, for any
        device it opens: a mapping file naming another is refused before anything
        starts (:func:`~.mapping.check_range`). None: not known (not checked; a plug-in
        that does not say).
    """

    name: str = ""
    help: str = ""
    library: str = ""
    extra: str = "inputs"
    default_map: str = ""
    device_axes: int | None = None
    device_buttons: int | None = None

    def add_arguments(self, group: argparse._ArgumentGroup) -> None:  # noqa: B027  (optional)
        """The backend's own flags (all backends' appear in ``sctd input --help``)."""

    @abstractmethod
    def missing(self) -> str | None:
        """None when the library imports, else why not (without raising)."""

    @abstractmethod
    def devices(self) -> list[DeviceInfo]:
        """The devices it sees now (no network discovery)."""

    @abstractmethod
    def open(self, selector: str | None, args: argparse.Namespace) -> InputDevice:
        """The device ``selector`` names (an index or part of a name; None: the first),
        configured from ``args``; raises :class:`InputError` when there is none."""

    def run_special(self, args: argparse.Namespace) -> int | None:
        """A backend's own job instead of the bridge (e.g. ``--calibrate``): its exit
        code, or None to run the bridge."""
        return None


def pick(devices: list[DeviceInfo], selector: str | None, backend: str) -> DeviceInfo:
    """The device ``selector`` names among ``devices``: an index, else the first whose
    name contains it (case-insensitive); None picks the first."""
    if not devices:
        raise InputError(f"{backend}: no device found")
    if selector is None:
        return devices[0]
    if selector.isdigit():
        for d in devices:
            if d.index == int(selector):
                return d
    else:
        for d in devices:
            if selector.lower() in d.name.lower():
                return d
    seen = "; ".join(f"{d.index}: {d.name}" for d in devices)
    raise InputError(f"{backend}: --device {selector!r} matches none of the devices ({seen})")
