"""The gripper's commands: grasp presses and a skill's entry actions in, the
``sctd/<robot>/gripper`` messages out (docs/wire-contract.md, "The gripper"). Pure: no
I/O, no clocks; times are arguments.

:class:`GripperControl` is the tick driver's (:mod:`.driver`): each tick it takes the
grasp presses the input arbiter let through (:class:`~.arbiter.GraspPress`: of the
device that owns the motion, or of any while nobody does), the gripper action of a
state a transition entered (:meth:`~sctd.skill.SkillEngine.take_entry_action`) and the
newest fresh reading, and says which message to put this tick, if any.

What a press does:

- while the reading says the fingers hold something (``grasped``), or nothing is known
  of them (no fresh reading) and the last command closed them, a press only starts a
  **hold**: the open is sent when the same device has held grasp for ``open_hold`` s
  (its newest message fresh, enabled, holding grasp, the device owning the motion or
  nobody; :meth:`~.arbiter.InputArbiter.holding`). A release, a stale or disabled
  input, another device taking the motion, a stop or a fault before that ends the hold
  and sends nothing (``cancelled``): a tremor cannot drop a cup;
- otherwise a press toggles: after a ``close`` (the fingers met nothing) it opens, else
  it closes with ``force`` N.

A press while a stop holds, or in the tick a stop was asked for, does nothing
(``cancelled``). Nothing else sends a command: a stop, a fault, a released deadman,
stale input, a skill swap or the daemon's end never open the hand; what is held stays
held. A state's entry action is sent once per entry, ``in_seq`` -1 and ``in_device``
"".

The newest command is sent at once and repeated every :data:`REPEAT` s (its ``cmd``
unchanged, a new ``seq`` and ``stamp``), for the whole run: a lost message costs
nothing, and a robot carries each ``cmd`` out once. ``cmd`` numbers go up from a
per-run start (the daemon's: its start time in ms), so that a restarted runtime's
commands are never taken for repeats of the previous run's.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

from ..skill import GripperAction
from ..wire.codec import GripperCmd, GripperReading
from .arbiter import GraspPress

REPEAT = 0.1  # s between repeats of the newest command (the wire contract: >= 10 Hz)


class _Hold(NamedTuple):
    """A grasp press that opens only when held: its device, seq, arrival, and the stop
    count when it began."""

    device: str
    seq: int
    since: float
    stops: int


class GripperControl:
    """The gripper's side of the tick (module doc).

    Parameters
    ----------
    force : float
        N: the force bound of a close the grasp button asks for.
    open_hold : float
        s grasp must be held to open a hand that holds something.
    cmd_start : int
        The first command number of the run.
    """

    def __init__(self, force: float, open_hold: float, cmd_start: int = 0):
        self.force, self.open_hold = force, open_hold
        self.next_cmd = cmd_start
        self.current: GripperCmd | None = None  # the newest command sent (seq, stamp of its newest put)
        self.source = ""  # what asked for it: "input" or "skill"
        self._due = 0.0  # when its next repeat is due
        self._intent = ""  # the newest action asked for (the toggle's memory)
        self._pending: GripperCmd | None = None  # asked for this tick, not yet numbered
        self.hold: _Hold | None = None
        self._stops = 0  # the stop count last seen
        self.reading: GripperReading | None = None  # the robot's newest, and its arrival
        self.reading_received: float | None = None
        self.commands = 0  # command numbers used
        self.messages = 0  # messages put, repeats included
        self.presses = 0  # grasp presses acted on (a toggle or a hold begun)
        self.cancelled = 0  # holds ended before the open, presses during a stop

    def observe(self, reading: GripperReading | None, received: float) -> None:
        """The newest robot state's gripper reading (None: it reports no gripper)."""
        if reading is not None:
            self.reading, self.reading_received = reading, received

    def step(self, now: float, wall: float, grasps: tuple[GraspPress, ...], entry: GripperAction | None,
             skill: str, grasped: bool | None, holding: Callable[[str], bool], stops: int,
             fault: bool) -> GripperCmd | None:
        """One tick: the message to put now (a new command or a repeat), or None.

        Parameters
        ----------
        now, wall : float
            The tick's monotonic time (the arrivals' clock) and Unix time (the stamp).
        grasps : tuple of GraspPress
            The grasp presses that act this tick (:attr:`~.arbiter.Command.grasps`).
        entry : GripperAction or None
            The action of the state a transition entered this tick.
        skill : str
            The running skill's id.
        grasped : bool or None
            The newest state's reading, when that state is fresh; None otherwise.
        holding : callable
            ``holding(device)``: whether the device still holds grasp so that it acts.
        stops : int
            Stop requests so far (``counters.stops``).
        fault : bool
            The tick is in mode ``fault`` (the arm reported one, or its state jumped).
        """
        stopped, self._stops = stops != self._stops, stops
        for p in grasps:
            for _ in range(p.presses):
                self._press(p, skill, grasped, stops, stopped)
        if self.hold is not None:
            self._watch_hold(now, skill, holding, stops, fault)
        if entry is not None:
            self._ask(GripperCmd(0, 0.0, 0, entry.action, entry.width, entry.force, entry.speed, skill),
                      "skill")
        return self._put(now, wall)

    def _press(self, p: GraspPress, skill: str, grasped: bool | None, stops: int, stopped: bool) -> None:
        if stopped:
            self.cancelled += 1
            return
        self.presses += 1
        if grasped or (grasped is None and self._intent == "close"):
            self.hold = _Hold(p.device, p.seq, p.received, stops)
            return
        self.hold = None
        if self._intent == "close":  # closed on nothing: a press opens
            self._ask(GripperCmd(0, 0.0, 0, "open", skill=skill, in_seq=p.seq, in_device=p.device), "input")
        else:
            self._ask(GripperCmd(0, 0.0, 0, "close", force=self.force, skill=skill, in_seq=p.seq,
                                 in_device=p.device), "input")

    def _watch_hold(self, now: float, skill: str, holding: Callable[[str], bool], stops: int,
                    fault: bool) -> None:
        """The hold under way: opens when held long enough, ends on anything else."""
        h = self.hold
        assert h is not None
        if fault or stops != h.stops or not holding(h.device):
            self.hold = None
            self.cancelled += 1
        elif now - h.since >= self.open_hold:
            self.hold = None
            self._ask(GripperCmd(0, 0.0, 0, "open", skill=skill, in_seq=h.seq, in_device=h.device), "input")

    def _ask(self, c: GripperCmd, source: str) -> None:
        """A new command, numbered when it is put (the newest of a tick wins)."""
        self._pending, self.source, self._intent = c, source, c.action

    def _put(self, now: float, wall: float) -> GripperCmd | None:
        c = self._pending
        if c is not None:
            self._pending = None
            self.commands += 1
            c = c._replace(cmd=self.next_cmd)
            self.next_cmd += 1
            self._due = now
        elif self.current is None or now < self._due:
            return None
        else:
            c = self.current
        self._due += REPEAT
        if self._due <= now:  # (a tick far behind: the next repeat a period from now)
            self._due = now + REPEAT
        self.current = c = c._replace(seq=self.messages, stamp=wall)
        self.messages += 1
        return c

    def status(self, now: float, ignored: int) -> dict[str, Any]:
        """``status.gripper`` at ``now`` (monotonic); ``ignored``: grasp presses of a
        device that did not own the motion."""
        c, r = self.current, self.reading
        return {
            "commands": self.commands,
            "messages": self.messages,
            "cmd": None if c is None else c.cmd,
            "action": None if c is None else c.action,
            "source": self.source or None,
            "in_device": None if c is None else c.in_device,
            "reading": None if r is None else {"width": r.width, "grasped": r.grasped, "moving": r.moving,
                                               "cmd": r.cmd},
            "reading_age": None if self.reading_received is None else round(now - self.reading_received, 6),
            "holding": None if self.hold is None else {"device": self.hold.device,
                                                        "held": round(now - self.hold.since, 3)},
            "presses": self.presses,
            "ignored_presses": ignored,
            "cancelled": self.cancelled,
        }
