"""Several input devices, one motion: per-device newest samples, buttons and the
ownership rule of the wire contract (docs/wire-contract.md, "Several devices"). Pure:
no I/O, no clocks; times are arguments.

Every arriving input message is offered here, in arrival order per device
(:meth:`InputArbiter.offer`); each tick asks once for the command it follows
(:meth:`InputArbiter.select`). The rule:

- a message is **at rest** when its command is zero (after the dead band), not finite,
  or its deadman (``buttons[1]``) is released; a device is at rest when its newest
  message is, and **stale** when that message is older than the input timeout;
- while no device owns the motion, the device whose push (a message not at rest) began
  first takes it at the next tick; it owns the motion until its newest message is at
  rest or stale;
- a device that pushes while another owns the motion is ignored and counted
  (``ignored_input``) and **disarmed**: it must send a zero command before it can take
  the motion (no takeover by a stick that was already deflected); so must a device
  whose deadman was released, or whose reading was not finite, with the stick
  deflected (zero-start: enabling again alone never restarts motion);
- **stale-disarm**: a device whose push went stale (its newest message, not at rest,
  older than the input timeout: a stalled or dropped link) loses the motion at once
  (zero command); if its push stays stale for longer than ``stale_grace`` it is
  disarmed too, counted once (``stale_disarms``): when its messages come back with the
  stick still deflected, they move nothing until it has sent a zero command, so a stick
  held through a stall never resumes the motion by itself. Within the grace (a
  person's reaction time: they cannot yet have seen the arm stop) fresh input takes the
  motion back as the person holds it, so that a sender's or a link's hiccup does not
  make them centre the stick. No ramp is added after the zero: the motion then starts
  from the person's own push from the centre, bounded per tick by the maximum speeds
  like any other start;
- a message with ``stop`` set, from any device, ends the ownership at the next tick and
  disarms every device; while any device's fresh newest message holds ``stop``, nobody
  takes the motion; afterwards the motion resumes only from a device that sent a zero
  command and then pushes again;
- :meth:`InputArbiter.summary` names the devices that must send a zero before they
  can move the arm, and why (``stale``, ``stop``, ``ignored``, ``released``), for the
  person's display;
- button presses (rising edges) are counted per device on every message; a tick acts on
  a device's presses when its newest message is fresh and enabled and the device owns
  the motion or nobody does (others are counted as ``ignored_presses``);
- presses of grasp (button 4) are also handed on with the device and the ``seq`` of the
  message that pressed it (:class:`GraspPress`, for the gripper: :mod:`.gripper`), and
  :meth:`InputArbiter.holding` says whether a device still holds grasp under the same
  rule (fresh, enabled, owning the motion or nobody does, no stop holding).

Ownership changes only at a tick, and what a message does depends on its own device's
messages and the owner the last tick left: messages of different devices that arrive
between two ticks have no order the receiver can know (a daemon drains them ring by
ring), and the outcome does not depend on the order they are offered in. Two pushes
that begin between the same two ticks are ordered by arrival time, then by name.

At most ``max_devices`` device names are tracked; a new name when the table is full
takes the place of a device that is armed, owns nothing and has been silent for
``evict_after`` s, or is dropped and counted (``input_devices_full``).
"""

from __future__ import annotations

from typing import NamedTuple

from ..wire.codec import BUTTON_ENABLE, BUTTON_GRASP, InputMsg
from .safety import sanitize_input

MAX_DEVICES = 64  # device names one daemon tracks at once
EVICT_AFTER = 10.0  # s a device must be silent before a new name may take its place
STALE_GRACE = 0.2  # s a push may stay stale and take the motion back: a simple visual reaction time
# Why a device must send a zero command before it can take the motion (status.input.rearm):
# its push went stale; a stop; it pushed while another device owned the motion; its
# deadman was released (or its reading was not finite) with the stick deflected.
DISARMED_BY = ("stale", "stop", "ignored", "released")


class ButtonWatch:
    """Rising edges of one device's buttons, counted message by message (so that a press
    is not lost when a tick sees only the newest of several messages)."""

    __slots__ = ("_last", "presses")

    def __init__(self) -> None:
        self._last: tuple[int, ...] = ()
        self.presses: tuple[int, ...] = ()

    def observe(self, buttons: tuple[int, ...]) -> tuple[int, ...]:
        """Take one message's buttons; the press counts so far."""
        last, counts = self._last, list(self.presses)
        if len(counts) < len(buttons):
            counts += [0] * (len(buttons) - len(counts))
        for i, b in enumerate(buttons):
            if b and not (i < len(last) and last[i]):
                counts[i] += 1
        self._last = buttons
        self.presses = tuple(counts)
        return self.presses


class GraspPress(NamedTuple):
    """Presses of grasp (button 4) that act: the device, the ``seq`` of its newest
    message with a rising edge of grasp and that message's arrival (the receiver's
    clock), and how many presses since the last tick (one but for a flood)."""

    device: str
    seq: int
    received: float
    presses: int = 1


class Command(NamedTuple):
    """What a tick follows: the command ``u`` (clipped, dead band applied; zeros when no
    device drives the motion), whether the input behind it is fresh, enabled and finite
    (``ok``), the ``seq`` and device of that input (-1 and "" for none), the buttons
    pressed since the last tick that act on it, and the grasp presses among them with
    the message that pressed (``grasps``)."""

    u: tuple[float, ...]
    ok: bool
    in_seq: int
    device: str
    pressed: frozenset[int]
    grasps: tuple[GraspPress, ...] = ()


NO_INPUT = Command((0.0, 0.0, 0.0), False, -1, "", frozenset())


class _Device:
    """One device's newest message and its standing under the rule."""

    __slots__ = ("acted", "armed", "buttons", "disarmed_by", "enabled", "finite", "grasp_received",
                 "grasp_seq", "msg", "name", "received", "rest", "run_start", "stale_from", "stale_seq",
                 "stop", "u")

    def __init__(self, name: str):
        self.name = name
        self.msg: InputMsg | None = None
        self.received = 0.0  # arrival of the newest message (the receiver's clock)
        self.u: tuple[float, ...] = ()  # its command (clipped, dead band applied)
        self.finite = True
        self.enabled = True
        self.rest = True
        self.stop = False  # the newest message holds stop
        self.armed = True
        self.disarmed_by = ""  # why it must send a zero first (DISARMED_BY), "" while armed
        self.run_start = 0.0  # arrival of the first message of the current push
        self.stale_from = 0.0  # the tick its push went stale (while lapsed: module doc)
        self.buttons = ButtonWatch()
        self.acted: tuple[int, ...] = ()  # press counts already acted on (or dropped)
        self.stale_seq = -1  # the newest message already counted as stale
        self.grasp_seq = -1  # the newest message with a rising edge of grasp, and its arrival
        self.grasp_received = 0.0


class InputArbiter:
    """Per-device input slots and the ownership rule (module doc).

    Parameters
    ----------
    input_timeout : float
        Seconds after which a device's newest message is stale (by arrival and, with
        ``stamp_check``, by its sender stamp against ``wall``).
    deadband : float
        Per-axis dead band of the command.
    counters
        The runtime's counters (``Counters``): input drops and events are counted there.
    stale_grace : float
        Seconds a push may stay stale and still take the motion back without a zero
        first (module doc, stale-disarm); 0: never.
    """

    def __init__(self, input_timeout: float, deadband: float, stamp_check: bool, counters,
                 max_devices: int = MAX_DEVICES, evict_after: float = EVICT_AFTER,
                 stale_grace: float = STALE_GRACE):
        self.input_timeout = input_timeout
        self.stale_grace = stale_grace
        self.deadband = deadband
        self.stamp_check = stamp_check
        self.counters = counters
        self.max_devices = max_devices
        self.evict_after = evict_after
        self.devices: dict[str, _Device] = {}
        self.owner: _Device | None = None
        self.last: _Device | None = None  # the device heard last
        self._stop_requested = False
        self._pending: list[_Device] = []  # armed devices that pushed while nobody owned
        self._pressing: list[_Device] = []  # devices with presses not yet seen by a tick
        self._stopping: set[_Device] = set()  # devices whose newest message holds stop
        self._lapsed: list[_Device] = []  # armed devices whose push went stale, within the grace
        self.ignored_grasps = 0  # grasp presses of a device while another owned the motion

    def at_rest(self) -> bool:
        """Whether every device's newest message is at rest (zero, not finite or
        disabled), fresh or stale: a stick held while its messages stopped is not at
        rest (it may come back deflected)."""
        return all(d.rest for d in self.devices.values())

    # --- every message, as it arrives ----------------------------------------------------

    def offer(self, name: str, m: InputMsg, now: float) -> bool:
        """Take one input message from device ``name`` that arrived at ``now``. Returns
        False when it was dropped (the device table is full).

        What a message does depends only on its own device's messages and on the owner
        as the last tick left it, so messages of different devices arriving between two
        ticks may be offered in any order: ownership changes only at :meth:`select`."""
        d = self.devices.get(name)
        if d is None:
            d = self._admit(name, now)
            if d is None:
                self.counters.drop("input_devices_full")
                return False
        d.msg, d.received = m, now
        last = self.last
        if last is None or now > last.received or (now == last.received and name >= last.name):
            self.last = d
        u, finite = sanitize_input(m.u, self.deadband)
        b = m.buttons
        enabled = not (len(b) > BUTTON_ENABLE and not b[BUTTON_ENABLE])
        if not finite:
            self.counters.nonfinite_input += 1
        elif not enabled:
            self.counters.disabled_input += 1
        was_rest = d.rest
        d.u, d.finite, d.enabled = u, finite, enabled
        d.rest = not (finite and enabled and any(u))
        if b:
            before = d.buttons.presses
            counts = d.buttons.observe(b)
            if counts != d.acted and d not in self._pressing:
                self._pressing.append(d)
            if len(counts) > BUTTON_GRASP and (len(before) <= BUTTON_GRASP
                                               or counts[BUTTON_GRASP] != before[BUTTON_GRASP]):
                d.grasp_seq, d.grasp_received = m.seq, now
        if m.stop and not d.stop:
            self.counters.stops += 1
            self._stop_requested = True
        d.stop = m.stop
        if m.stop:
            self._stopping.add(d)
        else:
            self._stopping.discard(d)
        if d.rest:
            self._settle(d, finite and not any(u))
            return True
        if was_rest:
            d.run_start = now
        owner = self.owner
        if owner is d:
            return True
        if owner is not None or self._stopping:
            self._ignore(d)
        elif d.armed and d not in self._pending:
            self._pending.append(d)
        return True

    def _settle(self, d: _Device, centred: bool) -> None:
        """A message at rest. Zero-start: only a centred stick re-arms a device. Releasing
        the deadman (or a broken, non-finite reading) with the stick deflected disarms it,
        so that enabling again alone never restarts motion."""
        if centred:
            d.armed, d.disarmed_by = True, ""
        elif d.armed:
            self._disarm(d, "released")

    def _ignore(self, d: _Device) -> None:
        self._disarm(d, "ignored")
        self.counters.ignored_input += 1

    @staticmethod
    def _disarm(d: _Device, why: str) -> None:
        """``d`` must send a zero command before it can take the motion; ``why`` (one of
        ``DISARMED_BY``) is kept for the person's display until it does."""
        if d.armed or d.disarmed_by != "stop":  # a stop stays the reason until the zero
            d.disarmed_by = why
        d.armed = False

    def _stale_push(self, d: _Device, now: float, wall: float) -> None:
        """``d``'s push went stale at the tick ``now`` (module doc, stale-disarm): the
        grace starts (it does not start again while the push stays stale)."""
        if d not in self._lapsed:
            d.stale_from = now
            self._lapsed.append(d)
        if self.stale_grace <= 0:
            self._lapse(now, wall)

    def _lapse(self, now: float, wall: float) -> None:
        """Disarm the devices whose push has been stale for longer than the grace; forget
        those that came to rest, were disarmed otherwise or took the motion back."""
        keep = []
        for d in self._lapsed:
            if d.rest or not d.armed or (d is self.owner and self.fresh(d, now, wall)):
                continue
            if now - d.stale_from >= self.stale_grace and not self.fresh(d, now, wall):
                self.counters.stale_disarms += 1
                self._disarm(d, "stale")
                continue
            keep.append(d)
        self._lapsed = keep

    def _admit(self, name: str, now: float) -> _Device | None:
        """A new device's slot, making room when the table is full (module doc)."""
        if len(self.devices) >= self.max_devices:
            old = next((d for d in self.devices.values() if d.armed and d is not self.owner
                        and d is not self.last and now - d.received >= self.evict_after), None)
            if old is None:
                return None
            del self.devices[old.name]
            self._stopping.discard(old)
            if old in self._pressing:
                self._pressing.remove(old)
        d = self.devices[name] = _Device(name)
        return d

    # --- once per tick --------------------------------------------------------------------

    def fresh(self, d: _Device, now: float, wall: float) -> bool:
        """Whether ``d``'s newest message is within the input timeout (arrival and, with
        the stamp check, its sender stamp)."""
        m = d.msg
        assert m is not None
        timeout = self.input_timeout
        return now - d.received <= timeout and (not self.stamp_check or abs(wall - m.stamp) <= timeout)

    def select(self, now: float, wall: float) -> Command:
        """The command this tick follows (module doc): the owner's newest message, or a
        zero command. Applies a stop, releases an owner at rest or stale, decides
        ownership among the devices that pushed since the last tick, and collects the
        presses that act."""
        if self._stop_requested:  # every device must come to rest and push again
            self._stop_requested = False
            self.owner = None
            for d in self.devices.values():
                d.armed, d.disarmed_by = False, "stop"
            self._pending.clear()
        owner = self.owner
        if owner is not None and (owner.rest or not self.fresh(owner, now, wall)):
            self._count_stale(owner, now, wall)
            if not owner.rest:  # stale while pushing (module doc, stale-disarm)
                self._stale_push(owner, now, wall)
            owner = self.owner = None
        if self._lapsed:
            self._lapse(now, wall)
        if self._stopping and not any(self.fresh(d, now, wall) for d in self._stopping):
            self._stopping.clear()  # stops that went stale no longer hold (the disarm stays)
        if owner is None and self._pending:
            owner = self._elect(now, wall)
        pressed, grasps = self._presses(now, wall) if self._pressing else (frozenset(), ())
        if owner is not None:
            m = owner.msg
            assert m is not None
            return Command(owner.u, True, m.seq, owner.name, pressed, grasps)
        last = self.last
        if last is None:
            return NO_INPUT
        m = last.msg
        assert m is not None
        ok = last.finite and last.enabled and self.fresh(last, now, wall)
        if not ok:
            self._count_stale(last, now, wall)
        return Command((0.0,) * len(last.u), ok, m.seq, last.name, pressed, grasps)

    def _elect(self, now: float, wall: float) -> _Device | None:
        """The pending device whose push began first (then by name: messages between two
        ticks have no order across devices) takes the motion; the others that push
        still are ignored (they must come to rest first)."""
        live = []
        for d in self._pending:
            if d.rest or not d.armed:
                continue
            if self.fresh(d, now, wall):
                live.append(d)
            else:  # its push went stale before it could take the motion
                self._stale_push(d, now, wall)
        self._pending.clear()
        if not live or self._stopping:
            for d in live:
                self._ignore(d)
            return None
        first = min(live, key=lambda d: (d.run_start, d.name))
        for d in live:
            if d is not first:
                self._ignore(d)
        self.owner = first
        return first

    def _presses(self, now: float, wall: float) -> tuple[frozenset[int], tuple[GraspPress, ...]]:
        """Presses since the last tick that act (module doc), and the grasp presses among
        them by device; the others are dropped."""
        pressed: set[int] = set()
        grasps: list[GraspPress] = []
        owner = self.owner
        for d in self._pressing:
            counts, last = d.buttons.presses, d.acted
            d.acted = counts
            new = [i for i, n in enumerate(counts)  # enable is held, not pressed
                   if i != BUTTON_ENABLE and n > (last[i] if i < len(last) else 0)]
            if not new or not (d.enabled and d.finite and self.fresh(d, now, wall)):
                continue
            n_grasp = counts[BUTTON_GRASP] - (last[BUTTON_GRASP] if len(last) > BUTTON_GRASP else 0) \
                if BUTTON_GRASP in new else 0
            if owner is not None and d is not owner:
                self.counters.ignored_presses += len(new)
                self.ignored_grasps += n_grasp
                continue
            pressed.update(new)
            if n_grasp:
                grasps.append(GraspPress(d.name, d.grasp_seq, d.grasp_received, n_grasp))
        self._pressing.clear()
        self.counters.presses += len(pressed)
        return frozenset(pressed), tuple(grasps)

    def holding(self, name: str, button: int, now: float, wall: float) -> bool:
        """Whether device ``name`` still holds ``button`` in a way that acts: its newest
        message is fresh, enabled, finite and holds the button, the device owns the
        motion or nobody does, and no device's stop holds."""
        d = self.devices.get(name)
        if d is None or d.msg is None:
            return False
        b = d.msg.buttons
        owner = self.owner
        return (len(b) > button and b[button] == 1 and d.enabled and d.finite and not self._stopping
                and not self._stop_requested and (owner is None or owner is d) and self.fresh(d, now, wall))

    @property
    def stopping(self) -> bool:
        """Whether a stop holds (a device's fresh newest message holds ``stop``) or was
        asked for since the last tick."""
        return bool(self._stopping) or self._stop_requested

    def _count_stale(self, d: _Device, now: float | None = None, wall: float | None = None) -> None:
        """Count ``d``'s newest message once as stale (when it is)."""
        m = d.msg
        assert m is not None
        if now is not None and wall is not None and self.fresh(d, now, wall):
            return
        if m.seq != d.stale_seq:
            d.stale_seq = m.seq
            self.counters.stale_input += 1

    def summary(self) -> dict[str, object]:
        """``status.input``: the device owning the motion (None), the number of devices
        tracked, whether a stop holds, and ``rearm``: the devices that must send a zero
        command before they can move the arm -> why (``DISARMED_BY``)."""
        return {"owner": self.owner.name if self.owner is not None else None,
                "devices": len(self.devices),
                "stop": bool(self._stopping),
                "rearm": {d.name: d.disarmed_by for d in self.devices.values() if not d.armed}}
