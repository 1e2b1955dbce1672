"""SDL, started once for every user in the process: the gamepad backend and the virtual
pad both hold one of SDL's reference counts on its joystick and game-controller
subsystems (a module of its own, so that neither imports the other)."""

from __future__ import annotations

import os
import threading
import warnings
from typing import Any

from .device import InputError

_lock = threading.Lock()


def import_sdl() -> Any:
    """PySDL2 (ImportError when it or its SDL2 library is missing)."""
    with warnings.catch_warnings():  # PySDL2 warns that it uses pysdl2-dll's binaries: wanted
        warnings.filterwarnings("ignore", message="Using SDL2 binaries", category=UserWarning)
        import sdl2
    return sdl2


def sdl_acquire() -> Any:
    """PySDL2 with SDL's joystick and game-controller subsystems initialised, headless;
    each call holds one of SDL's reference counts on them until :func:`sdl_release`.
    Raises InputError when SDL cannot start them."""
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
    try:
        sdl = import_sdl()
    except ImportError as e:
        raise InputError(f"gamepad: {MISSING} ({e})") from e
    with _lock:
        sdl.SDL_SetHint(sdl.SDL_HINT_JOYSTICK_ALLOW_BACKGROUND_EVENTS, b"1")
        if sdl.SDL_InitSubSystem(sdl.SDL_INIT_GAMECONTROLLER | sdl.SDL_INIT_JOYSTICK) != 0:
            raise InputError(f"gamepad: SDL_InitSubSystem: {sdl_error(sdl)}")
    return sdl


def sdl_release() -> None:
    """Give back one :func:`sdl_acquire` (SDL quits the subsystems at the last one,
    dropping virtual pads and added mappings)."""
    sdl = import_sdl()
    with _lock:
        sdl.SDL_QuitSubSystem(sdl.SDL_INIT_GAMECONTROLLER | sdl.SDL_INIT_JOYSTICK)


def sdl_error(sdl: Any) -> str:
    return (sdl.SDL_GetError() or b"").decode(errors="replace") or "unknown SDL error"


MISSING = "needs pysdl2 and pysdl2-dll: pip install 'sctd[inputs]'"
