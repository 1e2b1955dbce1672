"""Fault injection as a python-can bus wrapping another bus.

:class:`FaultInjectingBus` sits between an endpoint and its bus and, per frame and
direction, drops, delays, duplicates or corrupts frames, or refuses everything while
in bus-off, from a seeded generator so that runs repeat exactly. Delays are measured
on a caller-supplied clock (the simulation passes its simulated time), so a delayed
frame is released by the first ``send`` or receive at or after its due time.
"""

from __future__ import annotations

import heapq
import random
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can

from .virtual import drain as _drain


@dataclass
class FaultConfig:
    """What to inject, per frame, in each enabled direction.

    Attributes
    ----------
    drop_rate : float
        Probability a frame is lost.
    duplicate_rate : float
        Probability a frame is delivered twice.
    corrupt_rate : float
        Probability one data byte is xor-ed with a random non-zero value (always
        caught by the CRC-8, which detects any single-byte error).
    delay : float
        Delay, seconds of the wrapper's clock, given to delayed frames.
    delay_rate : float
        Probability a frame is delayed (1.0: every frame, a constant bus latency).
    bus_off : bool
        Start in bus-off: ``send`` raises :class:`can.CanOperationError`, nothing is
        received. Toggle with :meth:`FaultInjectingBus.set_bus_off`.
    tx, rx : bool
        Apply faults to sent and/or to received frames.
    seed : int
        Seed of the fault generator.
    """

    drop_rate: float = 0.0
    duplicate_rate: float = 0.0
    corrupt_rate: float = 0.0
    delay: float = 0.0
    delay_rate: float = 0.0
    bus_off: bool = False
    tx: bool = True
    rx: bool = False
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("drop_rate", "duplicate_rate", "corrupt_rate", "delay_rate"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"FaultConfig.{name}: {p} is not a probability in [0, 1]")
        if self.delay < 0.0:
            raise ValueError(f"FaultConfig.delay: {self.delay} is negative")


@dataclass
class FaultCounts:
    """What the wrapper actually injected (ground truth for detection tests)."""

    dropped: int = 0
    duplicated: int = 0
    corrupted: int = 0
    delayed: int = 0
    refused: int = 0


class FaultInjectingBus(can.BusABC):
    """A python-can bus that injects faults into the frames of a wrapped bus.

    Parameters
    ----------
    bus : can.BusABC
        The wrapped bus; shut down with this one.
    config : FaultConfig, optional
    clock : callable, optional
        Returns the current time in seconds for delays; default
        :func:`time.monotonic`.
    """

    def __init__(
        self,
        bus: can.BusABC,
        config: FaultConfig | None = None,
        clock: Callable[[], float] | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(channel=getattr(bus, "channel_info", "faults"), **kwargs)
        self.bus = bus
        self.config = config or FaultConfig()
        self.clock = clock or time.monotonic
        self.channel_info = f"faults on {getattr(bus, 'channel_info', bus)}"
        self.counts = FaultCounts()
        self._rng = random.Random(self.config.seed)
        self._bus_off = self.config.bus_off
        self._tx_held: list[tuple[float, int, can.Message]] = []
        self._rx_held: list[tuple[float, int, can.Message]] = []
        self._rx_ready: deque[can.Message] = deque()
        self._seq = 0

    # -- state -----------------------------------------------------------------------
    @property
    def state(self) -> can.BusState:
        """``ERROR`` while in bus-off, else ``ACTIVE``."""
        return can.BusState.ERROR if self._bus_off else can.BusState.ACTIVE

    @state.setter
    def state(self, new_state: can.BusState) -> None:
        self.set_bus_off(new_state == can.BusState.ERROR)

    def set_bus_off(self, on: bool = True) -> None:
        """Enter (``True``) or leave bus-off. Frames held for delay are lost on entry."""
        self._bus_off = bool(on)
        if on:
            self._tx_held.clear()
            self._rx_held.clear()
            self._rx_ready.clear()

    # -- fault logic -----------------------------------------------------------------
    def _apply(self, msg: can.Message, held: list[tuple[float, int, can.Message]]
               ) -> list[can.Message]:
        """Frames to pass on now for ``msg`` (0, 1 or 2), pushing delayed ones to ``held``."""
        cfg, rnd, n = self.config, self._rng.random, self.counts
        if cfg.drop_rate and rnd() < cfg.drop_rate:
            n.dropped += 1
            return []
        if cfg.corrupt_rate and rnd() < cfg.corrupt_rate:
            data = bytearray(msg.data)
            if data:
                data[self._rng.randrange(len(data))] ^= self._rng.randrange(1, 256)
            msg = _copy(msg, data)
            n.corrupted += 1
        out = [msg]
        if cfg.duplicate_rate and rnd() < cfg.duplicate_rate:
            out.append(_copy(msg, msg.data))
            n.duplicated += 1
        if cfg.delay_rate and rnd() < cfg.delay_rate:
            due = self.clock() + cfg.delay
            for m in out:
                self._seq += 1
                heapq.heappush(held, (due, self._seq, m))
            n.delayed += 1
            return []
        return out

    def _release(self, held: list[tuple[float, int, can.Message]]) -> list[can.Message]:
        now = self.clock()
        out = []
        while held and held[0][0] <= now:
            out.append(heapq.heappop(held)[2])
        return out

    # -- BusABC ----------------------------------------------------------------------
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` through the faults; raises :class:`can.CanOperationError` in bus-off."""
        if self._bus_off:
            self.counts.refused += 1
            raise can.CanOperationError("bus-off: transmitter switched off the bus")
        for m in self._release(self._tx_held):
            self.bus.send(m, timeout)
        frames = self._apply(msg, self._tx_held) if self.config.tx else [msg]
        for m in frames:
            self.bus.send(m, timeout)

    def send_batch(self, msgs: list[can.Message]) -> None:
        """Send one cycle's frames in order; stops at bus-off (raising)."""
        for m in msgs:
            self.send(m)

    def drain(self) -> list[can.Message]:
        """Every frame available now, after receive-side faults."""
        incoming = _drain(self.bus)
        if self._bus_off:
            return []
        out = list(self._rx_ready)
        self._rx_ready.clear()
        out.extend(self._release(self._rx_held))
        if not self.config.rx:
            out.extend(incoming)
            return out
        for m in incoming:
            out.extend(self._apply(m, self._rx_held))
        return out

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self._rx_ready:
            self._rx_ready.extend(self.drain())
        if not self._rx_ready and timeout:
            # Block on the wrapped bus once, then run the frame through the faults.
            m = self.bus.recv(timeout)
            if m is not None and not self._bus_off:
                self._rx_ready.extend(self._apply(m, self._rx_held) if self.config.rx else [m])
        if self._rx_ready:
            return self._rx_ready.popleft(), False
        return None, False

    def shutdown(self) -> None:
        """Shut down this wrapper and the wrapped bus."""
        super().shutdown()
        self.bus.shutdown()


def _copy(msg: can.Message, data: bytes | bytearray) -> can.Message:
    return can.Message(
        timestamp=msg.timestamp,
        arbitration_id=msg.arbitration_id,
        is_extended_id=msg.is_extended_id,
        channel=msg.channel,
        dlc=msg.dlc,
        data=bytearray(data),
        is_rx=msg.is_rx,
        check=False,
    )
