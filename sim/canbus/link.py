"""Receiver-side checks of the joint bus: what a frame is, and what was counted.

Every frame carries a 4-bit ``Counter`` (the SYNC cycle it belongs to) and a CRC-8.
A receiver classifies each arriving frame of a stream (one frame id) against the
last counter it accepted on that stream and the counter of the current cycle:

``corrupted``
    CRC mismatch; discarded.
``duplicated``
    same counter as the frame last accepted on the stream; discarded.
``stale``
    intact and new, but from an earlier cycle (delayed on the bus); discarded.
``accepted``
    current cycle. A gap to the last accepted counter adds to ``lost``.

Independently, ``missing`` counts cycles in which a stream that should have delivered
did not deliver a fresh frame (what the control loop feels, whatever the cause).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

ACCEPTED = 0
CORRUPTED = 1
DUPLICATED = 2
STALE = 3


@dataclass
class LinkStats:
    """Counters of one receiving endpoint (summed over its streams)."""

    received: int = 0
    accepted: int = 0
    corrupted: int = 0
    duplicated: int = 0
    stale: int = 0
    lost: int = 0
    missing: int = 0
    unknown: int = 0
    tx_errors: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain dict (for status messages and reports)."""
        return asdict(self)

    def check(self, data: bytes | bytearray, unpack) -> tuple[int, Any] | None:
        """Count a frame of a known stream as received and decode it with ``unpack``
        (``data -> (ok, counter, values)``); a frame that is not 8 bytes or fails its
        CRC is counted as corrupted and gives None, else ``(counter, values)``."""
        self.received += 1
        if len(data) != 8:
            self.corrupted += 1
            return None
        ok, counter, vals = unpack(data)
        if not ok:
            self.corrupted += 1
            return None
        return counter, vals

    def admit(self, counter: int, last: int | None, reference: int | None,
              got_this_cycle: bool) -> bool:
        """Classify an intact frame of one stream (see :func:`classify`), count the
        outcome, and return whether the frame is accepted."""
        if counter == reference and last != counter and not got_this_cycle:
            lost = 0 if last is None else (counter - last - 1) & 0xF  # the common case
        else:
            kind, lost = classify(counter, last, reference, got_this_cycle)
            if kind == DUPLICATED:
                self.duplicated += 1
                return False
            if kind != ACCEPTED:
                self.stale += 1
                return False
        self.accepted += 1
        self.lost += lost
        return True

    @property
    def faults(self) -> int:
        """Frames or cycles that were anything but clean."""
        return (self.corrupted + self.duplicated + self.stale + self.lost + self.missing
                + self.unknown + self.tx_errors)


def classify(counter: int, last: int | None, reference: int | None,
             got_this_cycle: bool) -> tuple[int, int]:
    """Classify an intact (CRC-checked) frame of one stream.

    Parameters
    ----------
    counter : int
        The frame's 4-bit counter.
    last : int or None
        Counter of the frame last accepted on this stream (None: none yet).
    reference : int or None
        Counter of the current cycle; None when the receiver has no cycle reference
        (then any counter 1..7 ahead of ``last`` is fresh, 8..15 ahead is stale).
    got_this_cycle : bool
        Whether this stream already delivered an accepted frame in this cycle.

    Returns
    -------
    kind : int
        :data:`ACCEPTED`, :data:`DUPLICATED` or :data:`STALE`.
    lost : int
        Frames skipped in the counter sequence, for an accepted frame.
    """
    if last is not None and counter == last and (got_this_cycle or reference != counter):
        return DUPLICATED, 0
    if reference is None:
        if last is None:
            return ACCEPTED, 0
        ahead = (counter - last) & 0xF
        if ahead >= 8:
            return STALE, 0
        return ACCEPTED, ahead - 1
    if counter != reference:
        return STALE, 0
    return ACCEPTED, 0 if last is None else (counter - last - 1) & 0xF
