"""SDL's virtual game controller, and a script that moves it on a timeline
(``docs/input-gamepad.md``).

A virtual joystick (``SDL_JoystickAttachVirtualEx``) exists only in the process that
creates it, so the tests and ``sctd bench input`` drive one inside the bridge's own
process: :class:`VirtualPad` in Python, or ``sctd input gamepad --virtual-script FILE``
(a hidden flag) with a :class:`Script` file. The pad is then found and opened by the
gamepad backend exactly as a real pad is (``--device``, ``devices()``, hot-plug).

Its axes and buttons are SDL's game-controller numbering (``SDL_CONTROLLER_AXIS_*``,
``SDL_CONTROLLER_BUTTON_*``): SDL gives a virtual controller the identity mapping
(``a:b0, b:b1, ..., leftx:a0, ..., righttrigger:a5``).

Script file (YAML or JSON), times in s from the bridge's first read::

    - {at: 0.0, button: 10, pressed: 1}   # right shoulder: the xbox map's deadman
    - {at: 0.5, axis: 1, value: -1.0}     # left stick pushed forward (SDL: y down +)
    - {at: 2.5, axis: 1, value: 0.0}
    - {at: 3.0, detach: true}             # unplugged
    - {at: 4.0, attach: true}             # plugged in again: axes at rest, buttons up

The pad is attached before the bridge opens its device.
"""

from __future__ import annotations

import ctypes
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sctd.files import FileError, load_yaml

from .device import InputError

NAME = "sctd virtual pad"
AXES = 6  # SDL_CONTROLLER_AXIS_MAX: left x, left y, right x, right y, triggers left, right
BUTTONS = 15  # SDL_CONTROLLER_BUTTON_A .. SDL_CONTROLLER_BUTTON_DPAD_RIGHT
TRIGGERS = (4, 5)
RAW_MAX = 32767


def raw_from_axis(axis: int, value: float) -> int:
    """The virtual joystick's raw value (-32768..32767) that SDL's controller reports as
    ``value``: sticks -1..1 as ``value * 32767``; triggers 0..1, which SDL's mapping
    rescales from the joystick's full range (``(raw + 32768) / 2``)."""
    if axis in TRIGGERS:
        return max(-32768, min(RAW_MAX, round(value * 65535.0 - 32768.0)))
    return max(-RAW_MAX, min(RAW_MAX, round(value * RAW_MAX)))


def _check_axis(axis: object, value: object, where: str) -> None:
    if type(axis) is not int or not 0 <= axis < AXES:
        raise InputError(f"{where}: axis: expected 0 to {AXES - 1}, got {axis!r}")
    low = 0.0 if axis in TRIGGERS else -1.0
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or not low <= value <= 1.0:
        what = "a trigger" if axis in TRIGGERS else "a stick"
        raise InputError(f"{where}: value: {what} axis takes {low:g} to 1, got {value!r}")


def _check_button(button: object, where: str) -> None:
    if type(button) is not int or not 0 <= button < BUTTONS:
        raise InputError(f"{where}: button: expected 0 to {BUTTONS - 1}, got {button!r}")


class VirtualPad:
    """A virtual game controller, attached while this object lives (a context manager).

    Parameters
    ----------
    name : str
        What SDL reports as its name (what ``--device`` matches).

    Notes
    -----
    Values reach a reader at its next ``SDL_GameControllerUpdate`` (the gamepad
    device's next read). The setters take SDL's joystick lock, so another thread may
    call them while the bridge reads.
    """

    def __init__(self, name: str = NAME):
        from .sdl import sdl_acquire, sdl_release

        self.name = name
        self._sdl = sdl_acquire()
        self._release = sdl_release
        self._joystick: Any = None
        self.instance_id = -1
        try:
            self.attach()
        except InputError:
            sdl_release()
            raise

    @property
    def attached(self) -> bool:
        return self._joystick is not None

    def attach(self) -> int:
        """Plug the pad in (axes at rest, buttons up); returns its SDL device index."""
        sdl = self._sdl
        if self.attached:
            raise InputError(f"{self.name}: already attached")
        desc = sdl.SDL_VirtualJoystickDesc()
        desc.version = sdl.SDL_VIRTUAL_JOYSTICK_DESC_VERSION
        desc.type = sdl.SDL_JOYSTICK_TYPE_GAMECONTROLLER
        desc.naxes, desc.nbuttons, desc.nhats = AXES, BUTTONS, 0
        desc.name = self.name.encode()
        index = sdl.SDL_JoystickAttachVirtualEx(ctypes.byref(desc))
        if index < 0:
            raise InputError(f"{self.name}: SDL_JoystickAttachVirtualEx: {_error(sdl)}")
        joystick = sdl.SDL_JoystickOpen(index)
        if not joystick:
            sdl.SDL_JoystickDetachVirtual(index)
            raise InputError(f"{self.name}: SDL_JoystickOpen: {_error(sdl)}")
        self._joystick = joystick
        self.instance_id = sdl.SDL_JoystickInstanceID(joystick)
        for axis in TRIGGERS:  # a released trigger is the joystick axis' minimum
            self.set_axis(axis, 0.0)
        return index

    def set_axis(self, axis: int, value: float) -> None:
        """Axis ``axis`` (SDL_CONTROLLER_AXIS_*) to ``value``: sticks -1..1 (y down +),
        triggers 0..1."""
        _check_axis(axis, value, self.name)
        if self._sdl.SDL_JoystickSetVirtualAxis(self._attached(), axis, raw_from_axis(axis, value)) < 0:
            raise InputError(f"{self.name}: SDL_JoystickSetVirtualAxis: {_error(self._sdl)}")

    def set_button(self, button: int, pressed: bool | int) -> None:
        """Button ``button`` (SDL_CONTROLLER_BUTTON_*) pressed or released."""
        _check_button(button, self.name)
        if self._sdl.SDL_JoystickSetVirtualButton(self._attached(), button, 1 if pressed else 0) < 0:
            raise InputError(f"{self.name}: SDL_JoystickSetVirtualButton: {_error(self._sdl)}")

    def detach(self) -> None:
        """Unplug the pad (readers see SDL_CONTROLLERDEVICEREMOVED)."""
        sdl = self._sdl
        self._attached()
        sdl.SDL_JoystickClose(self._joystick)
        self._joystick = None
        for index in range(sdl.SDL_NumJoysticks()):
            if sdl.SDL_JoystickGetDeviceInstanceID(index) == self.instance_id:
                if sdl.SDL_JoystickDetachVirtual(index) < 0:
                    raise InputError(f"{self.name}: SDL_JoystickDetachVirtual: {_error(sdl)}")
                return
        raise InputError(f"{self.name}: instance {self.instance_id} is gone from SDL's joysticks")

    def close(self) -> None:
        """Detach (when attached) and release SDL (idempotent)."""
        if self._sdl is None:
            return
        if self.attached:
            self.detach()
        self._sdl = None
        self._release()

    def _attached(self) -> Any:
        if self._sdl is None:
            raise InputError(f"{self.name}: closed")
        if self._joystick is None:
            raise InputError(f"{self.name}: not attached")
        return self._joystick

    def __enter__(self) -> VirtualPad:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _error(sdl: Any) -> str:
    return (sdl.SDL_GetError() or b"").decode(errors="replace") or "unknown SDL error"


@dataclass(frozen=True)
class Step:
    """One scripted change at ``at`` s: ``kind`` is ``axis``, ``button``, ``detach`` or
    ``attach``; ``index`` the axis or button; ``value`` its value (pressed: 0/1)."""

    at: float
    kind: str
    index: int = -1
    value: float = 0.0


KINDS = ("axis", "button", "detach", "attach")


def parse_script(doc: Any, origin: str) -> list[Step]:
    """The steps of a parsed script, in time order; InputError ``origin: [k]: problem``
    for a bad one, or one that moves a detached pad or plugs in an attached one."""
    if not isinstance(doc, list) or not doc:
        raise InputError(f"{origin}: expected a list of steps like {{at: 0.5, axis: 1, value: -1}}")
    steps = []
    for k, raw in enumerate(doc):
        where = f"{origin}: [{k}]"
        if not isinstance(raw, dict):
            raise InputError(f"{where}: expected a map with at and one of {', '.join(KINDS)}")
        kinds = [kind for kind in KINDS if kind in raw]
        if len(kinds) != 1:
            raise InputError(f"{where}: expected exactly one of {', '.join(KINDS)}, got {sorted(raw)}")
        kind = kinds[0]
        known = {"at", kind} | ({"value"} if kind == "axis" else {"pressed"} if kind == "button" else set())
        unknown = set(raw) - known
        if unknown:
            raise InputError(f"{where}.{sorted(map(str, unknown))[0]}: unknown field "
                             f"(known: {', '.join(sorted(known))})")
        at = raw.get("at")
        if isinstance(at, bool) or not isinstance(at, int | float) or not math.isfinite(at) or at < 0:
            raise InputError(f"{where}.at: expected seconds >= 0, got {at!r}")
        if kind == "axis":
            _check_axis(raw["axis"], raw.get("value"), where)
            steps.append(Step(float(at), kind, raw["axis"], float(raw["value"])))
        elif kind == "button":
            _check_button(raw["button"], where)
            pressed = raw.get("pressed")
            if pressed not in (0, 1) or isinstance(pressed, float):
                raise InputError(f"{where}.pressed: expected 0 or 1 (or true/false), got {pressed!r}")
            steps.append(Step(float(at), kind, raw["button"], float(pressed)))
        else:
            if raw[kind] is not True:
                raise InputError(f"{where}.{kind}: expected true, got {raw[kind]!r}")
            steps.append(Step(float(at), kind))
    order = sorted(range(len(steps)), key=lambda k: steps[k].at)
    attached = True
    for k in order:
        s = steps[k]
        if s.kind in ("axis", "button") and not attached:
            raise InputError(f"{origin}: [{k}]: the pad is detached at {s.at:g} s")
        if s.kind in ("detach", "attach") and attached == (s.kind == "attach"):
            raise InputError(f"{origin}: [{k}]: the pad is already {s.kind}ed at {s.at:g} s")
        attached = s.kind != "detach" if s.kind in ("detach", "attach") else attached
    return [steps[k] for k in order]


def load_script(path: str | Path) -> list[Step]:
    """The script file ``path`` (YAML or JSON); InputError naming the file and step."""
    p = Path(path)
    try:
        doc = load_yaml(p, file=f"--virtual-script {p}")
    except FileError as e:
        raise InputError(str(e)) from None
    return parse_script(doc, f"--virtual-script {p}")


class Script:
    """``steps`` played on ``pad``: :meth:`advance` applies the steps that are due, with
    time counted from its first call (the bridge's first read).

    A detach or an attach is the last step one call applies: the read that follows sees
    the pad unplugged (or plugged in) even when the reader fell behind the script's
    timeline, so that a late reader never skips an unplugging the script plays.

    Parameters
    ----------
    pad : VirtualPad
    steps : list of Step
        In time order (:func:`parse_script`).
    clock : callable, optional
        Seconds, monotonic (default ``time.monotonic``).
    """

    def __init__(self, pad: VirtualPad, steps: list[Step], clock=time.monotonic):
        self.pad = pad
        self.steps = steps
        self.clock = clock
        self.done = 0
        self._t0: float | None = None

    def advance(self) -> None:
        """Apply the steps due by now, up to and including the first detach or attach."""
        now = self.clock()
        if self._t0 is None:
            self._t0 = now
        t = now - self._t0
        while self.done < len(self.steps) and self.steps[self.done].at <= t:
            s = self.steps[self.done]
            self.done += 1
            if s.kind == "axis":
                self.pad.set_axis(s.index, s.value)
            elif s.kind == "button":
                self.pad.set_button(s.index, bool(s.value))
            elif s.kind == "detach":
                self.pad.detach()
                return
            else:
                self.pad.attach()
                return
