"""What the daemon reads, drained by the tick thread into the tick driver.

Every key the runtime reads arrives in a Zenoh ring channel that Zenoh's own threads
fill without Python (newest wins: a full ring loses its oldest message, never the
newest), so a flood costs the tick only the few messages it drains. The tick drains
each ring once per period, ahead of its deadline, checks each message's size before
copying it, and hands it to :meth:`~sctd.runtime.driver.TickDriver.receive`. Nothing
drops a message on arrival by rate: a rate limit keeps the first message of an interval
and drops the rest, and the rest may be a release.

The objects read are those the active skill names, by name: its task object and its
states' own (a skill set's: every member's).

Input devices each get a ring of their own, so that a device flooding its key can never
push another device's newest message out. Names are learned from a catch-all ring on
``input/*``: a message from a name without a ring is taken from there, and the device's
ring is declared after that tick; the next drain takes what arrived meanwhile from both
rings once (by payload) and from then on reads the device from its own ring. Messages
of further names are dropped and counted as ``input_devices_full`` (the arbiter decides
which names it tracks; a ring follows its table).

The devices' own rings are drained a message from each in turn, the first ring a
different one each drain, until they are empty or :data:`INPUT_BUDGET` messages are
taken: a flood on many device names costs a drain at most that many decodes and
judgements (each about 5 us on this project's VM, and more after a sleep), so the drain
stays within the tick's lead however many devices flood. What is left waits in its ring,
which keeps its newest messages, for the next drain: under such a flood a device's
newest message reaches the arbiter a few ticks late, never out of order, and
``counters.input_deferred`` counts the drains that stopped at the budget.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import Any

import zenoh

from ..skill import WORLD_OBJECT
from ..wire import Keys, codec
from .driver import TickDriver

log = logging.getLogger("sctd.run")

# Ring depths: the messages one drain can take from each ring; more in one period are
# coalesced in the ring (the oldest lost, the newest kept), which only happens when a
# sender exceeds its rate.
DEVICE_DEPTH = 4  # one input device (bridges send 20-1000 Hz)
ANY_DEPTH = 8  # the catch-all input ring: new names, and every device's copy to skip
STATE_DEPTH = 4  # the robot state (1 kHz)
OBJECT_DEPTH = 2  # one object's pose (perception 30-100 Hz)
INPUT_BUDGET = 4  # input messages one drain takes from the devices' own rings (module doc)


class Inlet:
    """One ring the tick drains: its subscription, depth, the size limit of its messages,
    the message kind (``input``, ``state``, ``object``) and the name passed along (the
    device or the object)."""

    __slots__ = ("depth", "kind", "limit", "name", "sub")

    def __init__(self, session: zenoh.Session, key: str, depth: int, limit: int, kind: str,
                 name: str = ""):
        self.sub = session.declare_subscriber(key, zenoh.handlers.RingChannel(depth))
        self.depth, self.limit, self.kind, self.name = depth, limit, kind, name

    def close(self) -> None:
        self.sub.undeclare()


def object_inlet(session: zenoh.Session, keys: Keys, name: str) -> Inlet:
    return Inlet(session, keys.objects(name), OBJECT_DEPTH, codec.MAX_OBJECT_BYTES, "object", name)


class Ingress:
    """The daemon's rings (module doc), drained into ``driver``.

    Parameters
    ----------
    session : zenoh.Session
    keys : Keys
    driver : TickDriver
    device : str
        ``*`` to follow every device (names learned as they appear), or one device name.
    """

    def __init__(self, session: zenoh.Session, keys: Keys, driver: TickDriver, device: str = "*"):
        self.session, self.keys, self.driver = session, keys, driver
        self.state = Inlet(session, keys.state, STATE_DEPTH, codec.MAX_STATE_BYTES, "state")
        self.any: Inlet | None = None
        self.devices: dict[str, Inlet] = {}  # key -> the device's own ring
        if device == "*":
            self.any = Inlet(session, keys.input("*"), ANY_DEPTH, codec.MAX_INPUT_BYTES, "input")
        else:
            self.devices[keys.input(device)] = self._device_inlet(device)
        self._wanted: list[str] = []  # names heard on the catch-all, to get a ring after the tick
        self._joining: dict[str, Inlet] = {}  # rings declared since the last drain
        self.objects: dict[str, Inlet] = {}
        names = set(driver.skill.objects()) | (driver.goals.objects if driver.goals is not None else set())
        for obj in sorted(names - {WORLD_OBJECT}):  # the skill's objects, or every set member's
            self.objects[obj] = object_inlet(session, keys, obj)
        self.trash: list[Any] = []  # oversized samples: freed off the tick thread (take_trash)
        self._turn = 0  # the device ring the next drain reads first

    def _device_inlet(self, name: str) -> Inlet:
        return Inlet(self.session, self.keys.input(name), DEVICE_DEPTH, codec.MAX_INPUT_BYTES,
                     "input", name)

    # --- the drain (tick thread, ahead of each deadline) ----------------------------------

    def drain(self, now: float) -> None:
        """Take what arrived since the last drain, ring by ring, into the driver."""
        if self.any is not None:
            self._drain_any(now)
        self._drain_devices(now)
        self._drain(self.state, now)
        for inlet in self.objects.values():
            self._drain(inlet, now)

    def _drain(self, inlet: Inlet, now: float) -> None:
        sub = inlet.sub
        for _ in range(inlet.depth):
            sample = sub.try_recv()
            if sample is None:
                break
            self._take(inlet.kind, inlet.name, sample, inlet.limit, now)

    def _drain_devices(self, now: float) -> None:
        """The devices' own rings, a message from each in turn, until they are empty or
        :data:`INPUT_BUDGET` messages are taken (module doc); each ring in its order. A
        drain that stops at the budget leaves the next one to begin at the ring it
        stopped at: round the rings, drain after drain."""
        devices = self.devices
        if len(devices) < 2:  # none, or one: the same rule on one ring, without the turns
            for inlet in devices.values():
                sub, taken = inlet.sub, 0
                while taken < DEVICE_DEPTH:
                    if taken == INPUT_BUDGET:
                        self._turn = 0
                        self.driver.counters.input_deferred += 1
                        return
                    sample = sub.try_recv()
                    if sample is None:
                        break
                    taken += 1
                    self._take("input", inlet.name, sample, inlet.limit, now)
            return
        inlets = list(devices.values())
        first = self._turn % len(inlets)
        rings = [(k % len(inlets), inlets[k % len(inlets)]) for k in range(first, first + len(inlets))]
        budget = INPUT_BUDGET
        for _ in range(DEVICE_DEPTH):
            more = []
            for k, inlet in rings:
                if budget == 0:
                    self._turn = k
                    self.driver.counters.input_deferred += 1
                    return
                sample = inlet.sub.try_recv()
                if sample is not None:
                    budget -= 1
                    self._take("input", inlet.name, sample, inlet.limit, now)
                    more.append((k, inlet))
            rings = more

    def _take(self, kind: str, name: str, sample: Any, limit: int, now: float) -> bytes | None:
        """Size-check, copy and hand one sample to the driver; its bytes (None when it
        was too large)."""
        payload = sample.payload
        if len(payload) > limit:
            self.driver.counters.drop(f"{kind}_too_large")
            self.trash.append(sample)  # freeing megabytes takes a while: not on the tick thread
            return None
        data = payload.to_bytes()
        try:
            self.driver.receive(kind, name, data, now)
        except Exception:  # a bug must cost one message, not the daemon
            log.exception("decoding a message on %s failed", sample.key_expr)
            self.driver.counters.drop("decoder_error")
        return data

    def _drain_any(self, now: float) -> None:
        """The catch-all input ring: messages of devices without a ring of their own yet
        (learning their names), skipping the copies of those that have one. A device
        whose ring was declared since the last drain is taken from both once, in arrival
        order: first what only the catch-all has, then its own ring."""
        assert self.any is not None
        joining = self._joining
        if not joining:
            self._drain_names(now)
            return
        seen: dict[str, set[bytes]] = {}
        batches: dict[str, list[Any]] = {}
        for key, inlet in joining.items():  # what arrived after its ring existed
            batch = batches[key] = []
            for _ in range(inlet.depth):
                sample = inlet.sub.try_recv()
                if sample is None:
                    break
                batch.append(sample)
            seen[key] = {s.payload.to_bytes() for s in batch if len(s.payload) <= inlet.limit}
        sub, devices = self.any.sub, self.devices
        for _ in range(ANY_DEPTH):
            sample = sub.try_recv()
            if sample is None:
                break
            key = str(sample.key_expr)
            if key in devices:
                continue
            if key in seen:
                if len(sample.payload) <= codec.MAX_INPUT_BYTES and sample.payload.to_bytes() in seen[key]:
                    continue
                self._take("input", joining[key].name, sample, codec.MAX_INPUT_BYTES, now)
                continue
            name = key.rsplit("/", 1)[-1]
            self._take("input", name, sample, codec.MAX_INPUT_BYTES, now)
            if name not in self._wanted and name in self.driver.inputs.devices:
                self._wanted.append(name)  # the arbiter took it in: its own ring after the tick
        for key, inlet in joining.items():
            for sample in batches[key]:
                self._take("input", inlet.name, sample, inlet.limit, now)
            devices[key] = inlet
        joining.clear()

    def _drain_names(self, now: float) -> None:
        """The catch-all ring while no device's ring is being handed over (every drain
        but the one after a ring is declared): the messages of names without a ring of
        their own, the copies of the others skipped (:meth:`_drain_any`)."""
        assert self.any is not None
        sub, devices = self.any.sub, self.devices
        for _ in range(ANY_DEPTH):
            sample = sub.try_recv()
            if sample is None:
                return
            key = str(sample.key_expr)
            if key in devices:
                continue
            name = key.rsplit("/", 1)[-1]
            self._take("input", name, sample, codec.MAX_INPUT_BYTES, now)
            if name not in self._wanted and name in self.driver.inputs.devices:
                self._wanted.append(name)  # the arbiter took it in: its own ring after the tick

    # --- between ticks ------------------------------------------------------------------

    def after_tick(self) -> None:
        """After the target is out: rings for the device names heard on the catch-all."""
        if not self._wanted:
            return
        known = set(self.driver.inputs.devices)
        for key in [k for k, inlet in self.devices.items() if inlet.name not in known]:
            self.devices.pop(key).close()  # the arbiter made room: its ring goes too
        for name in self._wanted:
            if name in known:
                self._joining[self.keys.input(name)] = self._device_inlet(name)
        self._wanted.clear()

    def take_trash(self) -> list[Any]:
        """The oversized samples drained since the last call, for another thread to drop
        (freeing a 10 MB payload costs about a millisecond)."""
        trash, self.trash = self.trash, []
        return trash

    # --- swaps ----------------------------------------------------------------------------

    def object_inlets(self, names: Iterable[str]) -> dict[str, Inlet]:
        """The rings of the objects ``names`` (a skill's object, or a skill set's
        members'; ``world`` needs none), reusing the current ones (called on the query's
        thread; installed by :meth:`use_objects` between ticks)."""
        out: dict[str, Inlet] = {}
        for obj in names:
            if obj != WORLD_OBJECT and obj not in out:
                inlet = self.objects.get(obj)
                out[obj] = inlet if inlet is not None else object_inlet(self.session, self.keys, obj)
        return out

    def use_objects(self, objects: dict[str, Inlet]) -> list[Inlet]:
        """Drain ``objects`` from now on (tick thread); returns the rings no longer
        drained, for the caller to close off the tick thread."""
        old = [inlet for name, inlet in self.objects.items() if name not in objects]
        self.objects = objects
        return old

    def close(self) -> None:
        for inlet in (self.state, self.any, *self.devices.values(), *self._joining.values(),
                      *self.objects.values()):
            if inlet is not None:
                inlet.close()
        self.devices, self._joining, self.objects = {}, {}, {}
