"""The bridge: a device read at a fixed rate, through the mapping file, published on
``sctd/<robot>/input/<name>`` by the wire contract (``docs/input.md``).

Safety, whatever the device does:

- every message is finite and within [-1, 1] (the mapping clips; a device's non-finite
  axis reads 0);
- the rate is fixed (default 100 Hz, never below 20 Hz), so a steady hand never trips the
  daemon's 0.1 s input watchdog, and a stopped bridge trips it at once;
- while the device is disconnected, and when the bridge stops (exit, error, signal), it
  publishes zero with the deadman released, so the arm holds without waiting for the
  watchdog.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from sctd.wire import codec

from .device import InputDevice, Reading
from .mapping import Mapping

MIN_RATE, MAX_RATE = 20.0, 1000.0
ZERO_ON_EXIT = 3  # zero messages published when the bridge stops
ZERO_SPACING = 0.005  # s between them (see Bridge.zero)


@dataclass
class BridgeStats:
    """Counters of one bridge's life."""

    published: int = 0
    disconnected: int = 0  # messages published as zero because the device was gone
    errors: int = 0  # reads that raised
    connects: int = 0
    last_error: str = ""
    events: list[str] = field(default_factory=list)


class Bridge:
    """``device`` -> ``mapping`` -> one input message per :meth:`step`.

    Parameters
    ----------
    device : InputDevice
    mapping : Mapping
    n_axes : int
        3 or 6: the length of ``u``.
    publish : callable
        ``publish(payload)`` with one encoded input message.
    log : callable, optional
        Where connect/disconnect and errors are said (default: stderr).
    """

    def __init__(self, device: InputDevice, mapping: Mapping, n_axes: int,
                 publish: Callable[[bytes], None], log: Callable[[str], None] | None = None):
        if n_axes not in (3, 6):
            raise ValueError(f"--axes: 3 or 6, got {n_axes}")
        self.device = device
        self.mapping = mapping
        self.n_axes = n_axes
        self.publish = publish
        self.log = log or (lambda s: print(s, file=sys.stderr, flush=True))
        self.seq = 0
        self.stats = BridgeStats()
        self.connected: bool | None = None
        self.last: tuple[list[float], list[int]] = ([0.0] * n_axes, self.mapping.released())
        self.last_reading: Reading | None = None

    def step(self, stamp: float | None = None) -> tuple[list[float], list[int]]:
        """Read the device once and publish what it maps to (zero while it is gone or its
        read fails); returns ``(u, buttons)`` as published."""
        stamp = time.time() if stamp is None else stamp
        try:
            reading = self.device.read()
        except Exception as e:  # a library error must not stop the zeros
            self.stats.errors += 1
            if str(e) != self.stats.last_error:
                self.stats.last_error = str(e)
                self.log(f"{self.device.name or 'device'}: read failed: {e}")
            reading = None
        self._connection(reading is not None)
        stop = False
        if reading is None:
            u, buttons = [0.0] * self.n_axes, self.mapping.released()
            self.stats.disconnected += 1
        else:
            u, buttons = self.mapping.apply(reading, self.n_axes)
            stop = self.mapping.stop(reading)
        self.last_reading = reading
        self._send(stamp, u, buttons, stop)
        return u, buttons

    def zero(self, count: int = ZERO_ON_EXIT, spacing: float = ZERO_SPACING) -> None:
        """Publish zero with the deadman released ``count`` times, ``spacing`` s apart (on
        exit). Spaced, so that a receiver that rate-limits its input (sctd daemons before
        per-device input slots dropped a message within 0.5 ms of the previous one) still
        gets one of them rather than keeping the last real message in force until its
        0.1 s watchdog."""
        for k in range(count):
            if k:
                time.sleep(spacing)
            self._send(time.time(), [0.0] * self.n_axes, self.mapping.released())

    def _send(self, stamp: float, u: list[float], buttons: list[int], stop: bool = False) -> None:
        self.seq += 1
        self.publish(codec.encode_input(self.seq, stamp, u, buttons, stop))
        self.stats.published += 1
        self.last = (u, buttons)

    def _connection(self, up: bool) -> None:
        if up == self.connected:
            return
        name = self.device.name or "device"
        if up:
            self.stats.connects += 1
            what = f"{name}: connected" if self.connected is None else f"{name}: reconnected"
        else:
            what = f"{name}: disconnected; publishing zero until it is back"
        self.connected = up
        self.stats.events.append(what)
        self.log(what)


def run(bridge: Bridge, rate: float, stop: threading.Event,
        on_tick: Callable[[Bridge], None] | None = None) -> None:
    """Step ``bridge`` at ``rate`` Hz until ``stop`` is set; zero on the way out."""
    from sctd.timing import Ticker, set_timer_slack

    if not MIN_RATE <= rate <= MAX_RATE:
        raise ValueError(f"--rate: between {MIN_RATE:g} and {MAX_RATE:g} Hz, got {rate:g}")
    set_timer_slack()
    ticker = Ticker(1.0 / rate)
    try:
        while not stop.is_set():
            ticker.wait()
            bridge.step()
            if on_tick is not None:
                on_tick(bridge)
    finally:
        bridge.zero(spacing=min(ZERO_SPACING, 1.0 / rate))
