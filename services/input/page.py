"""A browser page as an input device (``sctd try``, ``docs/try.md``).

The page reads a gamepad (the Gamepad API's standard mapping), the keyboard or an
on-screen stick and sends each reading, raw, over its socket. :class:`PageGate` is the
server's side of it, with no sockets in it: it checks every reading at the boundary,
maps it through a shipped mapping file (the same :class:`~.mapping.Mapping` the bridge of
``sctd input`` applies) and publishes it once on ``sctd/<robot>/input/<device>``, so the
daemon's arbiter takes the page as a device like any other.

Its rules (the safety of driving from a browser):

- **one page drives**: the first page connected is the controller; any page opened
  beside it is an observer, whose readings are refused and counted (``refused``);
- **a deadman**: the mapping's ``enable`` button (the pad's RB, the keyboard's Shift, a
  press on the stick); released, the command is zero;
- **checked, never trusted**: a reading that is not a map of the expected types, whose
  values are not finite or lie outside [-1, 1] (beyond :data:`TOLERANCE`), or whose
  ``seq`` is not newer than the last accepted one, is rejected and counted, and zero is
  published with the deadman released (a page that sends garbage does not keep the last
  good reading in force until the daemon's watchdog);
- **stale on hiding**: a page that is hidden, loses focus or whose socket closes stops
  the arm at once: zero with the deadman released is published (``stale``), and a hidden
  or unfocused page's readings are refused until it says it is back (``resume``);
- **never repeated**: every published message is a reading that just arrived or such a
  zero; the gate repeats nothing on its own, so a page that stops sending trips the
  daemon's input watchdog (0.1 s).
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from sctd.wire import codec

from .device import Reading
from .mapping import Mapping, shipped_mapping

DEVICE = "browser"  # the device name the page publishes under: sctd/<robot>/input/browser
SOURCES = {"gamepad": "browser-gamepad", "keyboard": "browser-page", "touch": "browser-page"}
TOLERANCE = 1e-6  # how far past [-1, 1] a value may round before it is out of range (then clipped)
MAX_AXES = 8  # a reading's axes at most (a standard gamepad has 4)
MAX_BUTTONS = 24  # its buttons at most (a standard gamepad has 17)
N_AXES = 3  # the length of the published u
N_BUTTONS = 5  # published: mode, enable, escape, choose, grasp (both maps map all five)


def check_reading(msg: Any, last_seq: int) -> tuple[str, Reading, int] | str:
    """``(source, reading, seq)`` of an input message from a page, or why it is rejected:
    ``type`` (not the expected fields and types), ``nonfinite``, ``range`` (a value
    outside [-1, 1]), ``old`` (``seq`` not newer than ``last_seq``)."""
    if not isinstance(msg, dict):
        return "type"
    seq, source, axes, buttons = msg.get("seq"), msg.get("source"), msg.get("axes"), msg.get("buttons", [])
    if type(seq) is not int or source not in SOURCES or not isinstance(axes, list) \
            or not isinstance(buttons, list) or not 0 < len(axes) <= MAX_AXES or len(buttons) > MAX_BUTTONS:
        return "type"
    if not all(type(x) in (int, float) for x in axes) or \
            not all(b is True or b is False or (type(b) is int and b in (0, 1)) for b in buttons):
        return "type"
    if not all(math.isfinite(x) for x in axes):
        return "nonfinite"
    if any(abs(x) > 1.0 + TOLERANCE for x in axes):
        return "range"
    if seq <= last_seq:
        return "old"
    clipped = tuple(max(-1.0, min(1.0, float(x))) for x in axes)
    return source, Reading(clipped, tuple(int(b) for b in buttons), time.time()), seq


class PageGate:
    """The pages' readings -> checked -> mapped -> published (one message each).

    Parameters
    ----------
    publish : callable
        ``publish(payload)`` with one encoded input message (``sctd/<robot>/input/browser``).
    mappings : dict, optional
        Source name -> :class:`Mapping` (default: the shipped ``browser-*.yaml`` maps).

    Every method is called from the server's thread and, for :meth:`report`, any other;
    a lock keeps them apart.
    """

    def __init__(self, publish: Callable[[bytes], None], mappings: dict[str, Mapping] | None = None):
        self.publish = publish
        self.mappings = mappings or {s: shipped_mapping(f) for s, f in SOURCES.items()}
        self._lock = threading.Lock()
        self.controller: int | None = None  # the connection that drives
        self.paused: str | None = None  # why the controller's readings are refused (hidden, blur)
        self.open = False  # whether a trial takes input
        self._page_seq = -1  # the newest seq accepted from the controller
        self.seq = 0  # of the published messages
        self.counts: Counter[str] = Counter()  # accepted, rejected:*, refused:*, stale:*, zeros
        self.last: dict[str, Any] = {"u": [0.0] * N_AXES, "buttons": [0] * N_BUTTONS, "stop": False,
                                     "source": None, "stamp": None}

    def connect(self, conn: int) -> str:
        """A page connected: its role, ``controller`` (the first) or ``observer``."""
        with self._lock:
            if self.controller is None:
                self.controller, self.paused, self._page_seq = conn, None, -1
                return "controller"
            return "observer"

    def role(self, conn: int) -> str:
        return "controller" if conn == self.controller else "observer"

    def disconnect(self, conn: int) -> None:
        """A page's socket closed: the controller's closing stops the arm."""
        with self._lock:
            if conn == self.controller:
                self.controller = None
                self._stale("closed")

    def reading(self, conn: int, msg: Any) -> str | None:
        """One input message from page ``conn``: None when published, else why not
        (``refused:observer``, ``refused:paused``, ``refused:closed``, ``rejected:*``)."""
        with self._lock:
            if conn != self.controller:
                return self._count("refused:observer")
            checked = check_reading(msg, self._page_seq)
            if isinstance(checked, str):
                self._zero()
                return self._count(f"rejected:{checked}")
            source, reading, seq = checked
            self._page_seq = seq
            if self.paused is not None:
                return self._count("refused:paused")
            if not self.open:
                return self._count("refused:closed")
            mapping = self.mappings[source]
            u, buttons = mapping.apply(reading, N_AXES)
            if not buttons[1]:  # the deadman released: zero, whatever the sticks say
                u = [0.0] * N_AXES
            self._send(u, buttons, mapping.stop(reading), source)
            self.counts["accepted"] += 1
            return None

    def garbage(self, conn: int) -> None:
        """A message from page ``conn`` that is not JSON, or of no known type."""
        with self._lock:
            if conn == self.controller:
                self._zero()
                self._count("rejected:type")
            else:
                self._count("refused:observer")

    def pause(self, conn: int, why: str) -> None:
        """The controller's page is hidden or lost focus (``why``): stop now."""
        with self._lock:
            if conn == self.controller:
                self.paused = why if why in ("hidden", "blur") else "hidden"
                self._stale(self.paused)

    def resume(self, conn: int) -> None:
        """The controller's page is visible and focused again: its readings count."""
        with self._lock:
            if conn == self.controller:
                self.paused = None

    def set_open(self, is_open: bool) -> None:
        """A trial starts (True) or ends (False: the arm stops)."""
        with self._lock:
            if self.open and not is_open:
                self._stale("trial over")
            self.open = is_open

    def report(self) -> dict[str, Any]:
        """The counters and the last message published (plain data, for the page)."""
        with self._lock:
            return {"counts": dict(self.counts), "last": dict(self.last), "paused": self.paused,
                    "open": self.open, "device": DEVICE}

    def _count(self, what: str) -> str:
        self.counts[what] += 1
        return what

    def _stale(self, why: str) -> None:
        self.counts[f"stale:{why}"] += 1
        self._zero()

    def _zero(self) -> None:
        self.counts["zeros"] += 1
        self._send([0.0] * N_AXES, [0] * N_BUTTONS, False, None)

    def _send(self, u: list[float], buttons: list[int], stop: bool, source: str | None) -> None:
        self.seq += 1
        stamp = time.time()
        self.publish(codec.encode_input(self.seq, stamp, u, buttons, stop))
        self.last = {"u": [round(x, 4) for x in u], "buttons": list(buttons), "stop": stop,
                     "source": source, "stamp": stamp, "seq": self.seq}
