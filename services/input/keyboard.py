"""The terminal's keys as a device, for trying a skill without one
(``docs/input-keyboard.md``).

Keys: the arrows move x (left/right) and y (up = forward, down = back); ``w``/``s``
or PageUp/PageDown move z (up/down); space or ``m`` is mode (button 0), ``e`` is escape
(button 2), ``x`` stop (3), ``c`` choose (4); Ctrl-C quits. There is no deadman: enable is always held.

A terminal sends a key's bytes on its press and again at each auto-repeat, never on its
release. So a key counts as held from its press until no repeat came for a while: for
``--key-hold`` seconds after the first press (longer than the terminal's delay before
it starts repeating, ~0.5 s), then ``--key-repeat-hold`` seconds after each repeat
(longer than the repeat period, ~0.03 s). :class:`KeyDecoder` and :class:`HoldTracker`
are pure (bytes and a clock in, keys out) and tested with a scripted clock.
"""

from __future__ import annotations

import argparse
import atexit
import os
import select
import sys
import time
from collections.abc import Callable
from typing import Any

from .device import Backend, DeviceInfo, InputDevice, InputError, Reading

# What a key does: (axis, sign) for motion, ("button", k) for a button.
AXIS_KEYS: dict[str, tuple[int, float]] = {
    "right": (0, 1.0), "left": (0, -1.0),
    "up": (1, 1.0), "down": (1, -1.0),
    "w": (2, 1.0), "pageup": (2, 1.0),
    "s": (2, -1.0), "pagedown": (2, -1.0),
}
BUTTON_KEYS: dict[str, int] = {" ": 0, "m": 0, "e": 2, "x": 3, "c": 4}  # 0 mode, 2 escape, 3 stop, 4 choose
N_BUTTONS = 5
ESCAPES = {b"[A": "up", b"[B": "down", b"[C": "right", b"[D": "left",
           b"OA": "up", b"OB": "down", b"OC": "right", b"OD": "left",  # application mode
           b"[5~": "pageup", b"[6~": "pagedown"}
HELP = ("keyboard: arrows move x (left/right) and y (up/down), w/s or PageUp/PageDown move z; "
        "space or m: mode; e: escape; x: stop; Ctrl-C quits. No deadman (enable held); a key holds "
        "while it auto-repeats.")


class KeyDecoder:
    """Terminal bytes -> key names (``"up"``, ``"pageup"``, ``"w"``, ``" "``...).

    An escape sequence split over two reads is completed by the next one; a sequence
    that is not one of :data:`ESCAPES` is dropped, and so is a lone ESC once a byte that
    cannot continue it follows. Letters are lower-cased.
    """

    def __init__(self) -> None:
        self._pending = b""
        self.unknown = 0

    def feed(self, data: bytes) -> list[str]:
        buf = self._pending + data
        self._pending = b""
        keys: list[str] = []
        i = 0
        while i < len(buf):
            c = buf[i]
            if c != 0x1B:
                ch = chr(c).lower() if c < 0x80 else ""
                if ch:
                    keys.append(ch)
                i += 1
                continue
            seq = buf[i + 1:]
            match = next((k for k in ESCAPES if seq.startswith(k)), None)
            if match is not None:
                keys.append(ESCAPES[match])
                i += 1 + len(match)
            elif any(len(seq) < len(k) and k.startswith(seq) for k in ESCAPES):
                self._pending = buf[i:]  # a prefix of a known sequence: wait for the rest
                break
            else:
                self.unknown += 1
                i += 1 + _sequence_length(seq)
        return keys


def _sequence_length(seq: bytes) -> int:
    """How many bytes after ESC an unknown CSI/SS3 sequence takes (0 for a lone ESC)."""
    if seq[:1] == b"O":
        return min(2, len(seq))
    if seq[:1] != b"[":
        return 0
    for n, c in enumerate(seq[1:], 2):
        if 0x40 <= c <= 0x7E:  # a CSI sequence's final byte
            return n
    return len(seq)


class HoldTracker:
    """Which keys count as held, from their presses and repeats alone.

    Parameters
    ----------
    first_hold : float
        Seconds a key stays held after its first press (longer than the terminal's
        delay before auto-repeat starts).
    repeat_hold : float
        Seconds it stays held after each repeat (longer than the repeat period).
    """

    def __init__(self, first_hold: float = 0.6, repeat_hold: float = 0.1):
        if not 0.0 < repeat_hold <= first_hold:
            raise ValueError(f"hold times: 0 < repeat ({repeat_hold}) <= first ({first_hold})")
        self.first_hold = first_hold
        self.repeat_hold = repeat_hold
        self._until: dict[str, float] = {}

    def press(self, key: str, t: float) -> None:
        """``key``'s bytes arrived at ``t`` (s): a first press, or a repeat while held."""
        held = self._until.get(key, -1.0) > t
        self._until[key] = t + (self.repeat_hold if held else self.first_hold)

    def held(self, t: float) -> set[str]:
        """The keys held at ``t``."""
        for k in [k for k, u in self._until.items() if u <= t]:
            del self._until[k]
        return set(self._until)


def reading_from_keys(held: set[str], speed: float, stamp: float) -> Reading:
    """x, y, z (each ``speed`` times the sum of its held keys' signs, in [-1, 1]) and
    the device's buttons (:data:`BUTTON_KEYS`)."""
    axes = [0.0, 0.0, 0.0]
    for k in held:
        if k in AXIS_KEYS:
            axis, sign = AXIS_KEYS[k]
            axes[axis] += sign
    u = tuple(max(-1.0, min(1.0, a * speed)) for a in axes)
    buttons = [0] * N_BUTTONS
    for k in held:
        if k in BUTTON_KEYS:
            buttons[BUTTON_KEYS[k]] = 1
    return Reading(u, tuple(buttons), stamp)


class TerminalKeys(InputDevice):
    """The terminal on ``fd`` in cbreak mode (no echo, no line buffering, Ctrl-C still
    a signal), read without blocking; its settings are restored by :meth:`close`, also
    at interpreter exit should close be skipped."""

    axes = 3
    buttons = N_BUTTONS

    def __init__(self, fd: int, tracker: HoldTracker, speed: float,
                 clock: Callable[[], float] = time.monotonic):
        import termios
        import tty

        self.name = os.ttyname(fd)
        self.fd = fd
        self.decoder = KeyDecoder()
        self.tracker = tracker
        self.speed = speed
        self._clock = clock
        self._saved: Any = termios.tcgetattr(fd)
        self._gone = False
        tty.setcbreak(fd)
        atexit.register(self.close)

    def read(self) -> Reading | None:
        if self._gone:
            return None
        now = self._clock()
        try:
            while select.select([self.fd], [], [], 0.0)[0]:
                data = os.read(self.fd, 1024)
                if not data:  # the terminal hung up
                    self._gone = True
                    return None
                for key in self.decoder.feed(data):
                    self.tracker.press(key, now)
        except OSError:
            self._gone = True
            return None
        return reading_from_keys(self.tracker.held(now), self.speed, time.time())

    def close(self) -> None:
        saved, self._saved = self._saved, None
        if saved is None:
            return
        import termios

        try:
            termios.tcsetattr(self.fd, termios.TCSADRAIN, saved)
        except termios.error:
            pass  # the terminal is gone: nothing to restore
        atexit.unregister(self.close)


class Keyboard(Backend):
    """The terminal's keys (stdin)."""

    name = "keyboard"
    help = "the terminal's keys, to try a skill without a device (arrows, w/s, space, e)"
    library = ""
    extra = ""
    default_map = "keyboard"
    device_axes = 3  # x, y, z (read_keys)
    device_buttons = N_BUTTONS

    def add_arguments(self, group: argparse._ArgumentGroup) -> None:
        group.add_argument("--key-hold", type=float, default=0.6, metavar="S",
                           help="seconds a key holds after its first press; longer than the "
                                "terminal's auto-repeat delay (default %(default)s)")
        group.add_argument("--key-repeat-hold", type=float, default=0.1, metavar="S",
                           help="seconds a key holds after each auto-repeat; longer than the "
                                "repeat period (default %(default)s)")
        group.add_argument("--key-speed", type=float, default=1.0, metavar="FRACTION",
                           help="axis value while a key is held, in (0, 1] (default %(default)s)")

    def missing(self) -> str | None:
        try:
            import termios  # noqa: F401
            import tty  # noqa: F401
        except ImportError:
            return "needs a POSIX terminal (termios)"
        return None

    def devices(self) -> list[DeviceInfo]:
        fd = _stdin_fd()
        if fd < 0:
            return []
        return [DeviceInfo(0, "terminal", os.ttyname(fd))]

    def open(self, selector: str | None, args: argparse.Namespace) -> InputDevice:
        if selector not in (None, "0") and "terminal".find(selector.lower()) < 0:
            raise InputError(f"keyboard: --device {selector!r}: the only device is 0: terminal")
        speed = args.key_speed
        if not 0.0 < speed <= 1.0:
            raise InputError(f"keyboard: --key-speed: in (0, 1], got {speed:g}")
        try:
            tracker = HoldTracker(args.key_hold, args.key_repeat_hold)
        except ValueError as e:
            raise InputError(f"keyboard: --key-hold/--key-repeat-hold: {e}") from e
        fd = _stdin_fd()
        if fd < 0:
            raise InputError("keyboard: stdin is not a terminal: run sctd input keyboard in one")
        device = TerminalKeys(fd, tracker, speed)
        print(HELP, file=sys.stderr, flush=True)
        return device


def _stdin_fd() -> int:
    """stdin's file descriptor when it is a terminal, else -1."""
    try:
        fd = sys.stdin.fileno()
    except (AttributeError, ValueError, OSError):  # None, closed, or replaced (pytest)
        return -1
    return fd if os.isatty(fd) else -1
