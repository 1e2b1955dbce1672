"""The gamepad backend: any pad SDL2's game-controller API knows, through PySDL2 with
the ``pysdl2-dll`` binaries (``docs/input-gamepad.md``).

SDL's game-controller API gives every pad in its mapping database (Xbox, PlayStation,
Switch Pro, Logitech, 8BitDo, ...) one layout: axes by ``SDL_CONTROLLER_AXIS_*`` (left
x, left y, right x, right y with y down +, left and right trigger) and buttons by
``SDL_CONTROLLER_BUTTON_*`` (A, B, X, Y, back, guide, start, left and right stick,
left and right shoulder, d-pad up, down, left, right, then misc, paddles, touchpad).
A :class:`~sctd_services.input.device.Reading` carries them in that order: sticks
``raw / 32767`` clipped to [-1, 1], triggers 0..1; the shipped ``maps/xbox.yaml`` maps
them to the wire contract. The database is SDL's built-in one, plus
``SDL_GAMECONTROLLERCONFIG`` / ``SDL_GAMECONTROLLERCONFIG_FILE`` as SDL reads them,
plus ``--gamepad-mappings FILE`` (gamecontrollerdb.txt lines).

Hot-plug: when the open pad is removed (``SDL_CONTROLLERDEVICEREMOVED``) reads return
None (the bridge publishes zero); when a controller the same ``--device`` selects is
added, the next read opens it. SDL is initialised headless (video and audio drivers
``dummy`` unless set; only its joystick and game-controller subsystems), with background
joystick events allowed.
"""

from __future__ import annotations

import argparse
import ctypes
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sctd.app.errors import fail

from .device import Backend, DeviceInfo, InputDevice, InputError, Reading, pick
from .sdl import MISSING as _MISSING
from .sdl import import_sdl as _import_sdl
from .sdl import sdl_acquire, sdl_error, sdl_release

BACKEND = "gamepad"
AXIS_MAX = 32767.0


def _guid(sdl: Any, index: int) -> str:
    buf = ctypes.create_string_buffer(33)
    sdl.SDL_JoystickGetGUIDString(sdl.SDL_JoystickGetDeviceGUID(index), buf, 33)
    return buf.value.decode()


def _scan(sdl: Any) -> list[tuple[DeviceInfo, bool]]:
    """Every joystick SDL sees, and whether it is a game controller (has a mapping)."""
    out = []
    for index in range(sdl.SDL_NumJoysticks()):
        controller = bool(sdl.SDL_IsGameController(index))
        raw = (sdl.SDL_GameControllerNameForIndex(index) if controller else None) \
            or sdl.SDL_JoystickNameForIndex(index) or b"?"
        guid = _guid(sdl, index)
        detail = (f"GUID {guid}" if controller else
                  f"not a game controller: no mapping for GUID {guid}; add one with --gamepad-mappings")
        out.append((DeviceInfo(index, raw.decode(errors="replace"), detail), controller))
    return out


def _choose(sdl: Any, selector: str | None) -> DeviceInfo:
    """The controller ``selector`` names (None: the first game controller); InputError
    naming the devices seen."""
    scanned = _scan(sdl)
    if selector is None:
        controllers = [d for d, ok in scanned if ok]
        if controllers:
            return controllers[0]
        if scanned:
            seen = "; ".join(f"{d.index}: {d.name} ({d.detail})" for d, _ in scanned)
            raise InputError(f"{BACKEND}: no game controller among the joysticks ({seen})")
    info = pick([d for d, _ in scanned], selector, BACKEND)
    if not dict((d.index, ok) for d, ok in scanned)[info.index]:
        raise InputError(f"{BACKEND}: {info.index}: {info.name}: {info.detail}")
    return info


class GamepadDevice(InputDevice):
    """An open game controller, reopened by its selector after it was unplugged.

    Parameters
    ----------
    sdl : module
        PySDL2, acquired (:func:`sdl_acquire`); released on :meth:`close`.
    selector : str or None
        What ``--device`` said: the controller looked for again after a removal.
    info : DeviceInfo
        The controller to open now.
    before_read : callable, optional
        Called first in every read (the virtual script's timeline).
    on_close : callable, optional
        Called on close, before SDL is released (the virtual pad's close).
    """

    def __init__(self, sdl: Any, selector: str | None, info: DeviceInfo,
                 before_read: Callable[[], None] | None = None,
                 on_close: Callable[[], None] | None = None):
        self._sdl = sdl
        self.selector = selector
        self.axes = sdl.SDL_CONTROLLER_AXIS_MAX
        self.buttons = sdl.SDL_CONTROLLER_BUTTON_MAX
        self._before_read = before_read
        self._on_close = on_close
        self._events = (sdl.SDL_Event * 16)()
        self._controller: Any = None
        self._instance = -1
        self.reopened = 0
        self._open(info.index)
        self.name = info.name

    def _open(self, index: int) -> None:
        sdl = self._sdl
        controller = sdl.SDL_GameControllerOpen(index)
        if not controller:
            raise InputError(f"{BACKEND}: SDL_GameControllerOpen({index}): {sdl_error(sdl)}")
        self._controller = controller
        self._instance = sdl.SDL_JoystickInstanceID(sdl.SDL_GameControllerGetJoystick(controller))

    def _drop(self) -> None:
        if self._controller is not None:
            self._sdl.SDL_GameControllerClose(self._controller)
            self._controller = None
            self._instance = -1

    def read(self) -> Reading | None:
        """Pump SDL (``SDL_GameControllerUpdate``, then its joystick and controller
        events), follow removal and re-adding, and return the controller's state; never
        blocks."""
        if self._sdl is None:
            raise InputError(f"{BACKEND}: {self.name}: closed")
        if self._before_read is not None:
            self._before_read()
        sdl = self._sdl
        sdl.SDL_GameControllerUpdate()
        removed, added = self._device_events()
        c = self._controller
        if c is not None and (removed or not sdl.SDL_GameControllerGetAttached(c)):
            self._drop()
        if self._controller is None:
            if not added:
                return None
            try:
                self._open(_choose(sdl, self.selector).index)
            except InputError:  # another pad, or none the selector names: keep waiting
                return None
            self.reopened += 1
        c = self._controller
        get_axis, get_button = sdl.SDL_GameControllerGetAxis, sdl.SDL_GameControllerGetButton
        axes = tuple(max(-1.0, min(1.0, get_axis(c, a) / AXIS_MAX)) for a in range(self.axes))
        buttons = tuple(int(get_button(c, b)) for b in range(self.buttons))
        return Reading(axes, buttons, time.time())

    def _device_events(self) -> tuple[bool, bool]:
        """Take SDL's queued joystick and controller events (state is read directly, so
        motion events are only drained); whether the open controller was removed and
        whether any controller was added."""
        sdl = self._sdl
        removed = added = False
        while True:
            n = sdl.SDL_PeepEvents(self._events, len(self._events), sdl.SDL_GETEVENT,
                                   sdl.SDL_JOYAXISMOTION, sdl.SDL_CONTROLLERSENSORUPDATE)
            for k in range(max(n, 0)):
                e = self._events[k]
                if e.type == sdl.SDL_CONTROLLERDEVICEREMOVED and e.cdevice.which == self._instance:
                    removed = True
                elif e.type == sdl.SDL_CONTROLLERDEVICEADDED:
                    added = True
            if n < len(self._events):
                return removed, added

    def close(self) -> None:
        if self._sdl is None:
            return
        self._drop()
        try:
            if self._on_close is not None:
                self._on_close()
        finally:
            self._sdl = None
            sdl_release()


class Gamepad(Backend):
    """Game controllers through SDL2 (PySDL2 + pysdl2-dll)."""

    name = BACKEND
    help = "game controllers (Xbox, PlayStation, Switch Pro, ...) through SDL2's game-controller API"
    library = "pysdl2 + pysdl2-dll"
    default_map = "xbox"
    # SDL's game-controller numbering (SDL_CONTROLLER_AXIS_MAX, SDL_CONTROLLER_BUTTON_MAX
    # of SDL 2.0.14 and later: up to the touchpad, 20)
    device_axes = 6
    device_buttons = 21

    def add_arguments(self, group: argparse._ArgumentGroup) -> None:
        group.add_argument("--gamepad-mappings", metavar="FILE",
                           help="more SDL controller mappings (gamecontrollerdb.txt lines) for pads "
                                "SDL's built-in database does not know")
        group.add_argument("--virtual-script", metavar="FILE", help=argparse.SUPPRESS)

    def run_special(self, args: argparse.Namespace) -> int | None:
        """No job of its own: checks the files its flags name first, so a bad one exits 2
        (a bad file) before any device is looked for."""
        try:
            mappings = getattr(args, "gamepad_mappings", None)
            if mappings and not Path(mappings).is_file():
                raise InputError(f"--gamepad-mappings {mappings}: no such file")
            if getattr(args, "virtual_script", None):
                from .virtual_pad import load_script

                load_script(args.virtual_script)
        except InputError as e:
            return fail("input", str(e))
        return None

    def missing(self) -> str | None:
        try:
            _import_sdl()
        except ImportError:
            return _MISSING
        return None

    def devices(self) -> list[DeviceInfo]:
        sdl = sdl_acquire()
        try:
            return [d for d, _ in _scan(sdl)]
        finally:
            sdl_release()

    def open(self, selector: str | None, args: argparse.Namespace) -> InputDevice:
        mappings = getattr(args, "gamepad_mappings", None)
        script_file = getattr(args, "virtual_script", None)
        steps = None
        if script_file:
            from .virtual_pad import load_script

            steps = load_script(script_file)
        sdl = sdl_acquire()
        pad = None
        try:
            if mappings:
                add_mappings(sdl, mappings)
            before_read = on_close = None
            if steps is not None:
                from .virtual_pad import Script, VirtualPad

                pad = VirtualPad()
                before_read, on_close = Script(pad, steps).advance, pad.close
            device = GamepadDevice(sdl, selector, _choose(sdl, selector), before_read, on_close)
        except BaseException:
            if pad is not None:
                pad.close()
            sdl_release()
            raise
        return device


def add_mappings(sdl: Any, path: str | Path) -> int:
    """Add the SDL mappings in ``path`` (gamecontrollerdb.txt format); how many."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"--gamepad-mappings {p}: no such file")
    n = sdl.SDL_GameControllerAddMappingsFromFile(str(p).encode())
    if n < 0:
        raise InputError(f"--gamepad-mappings {p}: {sdl_error(sdl)}")
    return int(n)
