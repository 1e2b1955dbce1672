"""The Franka Hand through franky's ``Gripper``, for the ``franky`` driver.

franky's gripper calls wait on the network (the hand's own server, beside the arm's
FCI), so the hand runs on a thread of its own: :meth:`FrankyHand.submit` hands it the
newest command and returns at once; the thread starts it with franky's asynchronous
call (stopping a motion still under way first) and reads the fingers' width and grasp
every ``READ_PERIOD`` s, which the driver puts in each reading.

The commands (``sctd/<robot>/gripper``, docs/wire-contract.md): ``open`` moves to the
width given, else the hand's widest; ``width`` moves to the width; ``close`` grasps:
it closes at the speed given until the fingers meet something, squeezing with the force
given (the hand's own force control holds it), and counts as grasped when the fingers
stopped above the width given less ``GRASP_EPSILON`` (without one, anywhere); fingers
closer than ``NOTHING_HELD`` hold nothing, whatever the hand says. The hand's own limits (its
widest opening, its speed and force ranges) stay in force: a width past its widest is
taken as its widest.
"""

from __future__ import annotations

import threading
from typing import Any

from sctd.wire.codec import MAX_GRIPPER_WIDTH, GripperCmd, GripperReading

READ_PERIOD = 0.05  # s between readings of the fingers
DEFAULT_SPEED = 0.05  # m/s when a command gives none (the Franka Hand's range is 0.01-0.2)
GRASP_EPSILON = 0.005  # m below the width given that still counts as grasped
NOTHING_HELD = 0.003  # m: fingers closer than this hold nothing


class FrankyHand:
    """A connected ``franky.Gripper`` (``gripper``) driven from its own thread."""

    def __init__(self, gripper: Any):
        self.g = gripper
        self.max_width = float(gripper.max_width)
        self.reading: GripperReading | None = None
        self.cmd = -1  # the newest command number started
        self.errors = 0
        self.last_error = ""
        self._pending: GripperCmd | None = None
        self._future: Any = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="franky-gripper", daemon=True)
        self._thread.start()

    def submit(self, c: GripperCmd) -> None:
        """Have the thread start ``c`` next (a newer one submitted before replaces it)."""
        with self._lock:
            self._pending = c

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def health(self) -> dict[str, Any]:
        return {"gripper_cmd": self.cmd, "gripper_errors": self.errors, "gripper_error": self.last_error}

    # -- the thread ----------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                c, self._pending = self._pending, None
            try:
                if c is not None:
                    self._start(c)
                st = self.g.state
                moving = self._future is not None and not self._future.wait(0)
                width = min(max(float(st.width), 0.0), MAX_GRIPPER_WIDTH)
                # (fingers closed on nothing hold nothing, whatever the grasp's bounds said)
                self.reading = GripperReading(width, bool(st.is_grasped) and width > NOTHING_HELD, moving,
                                              self.cmd)
            except Exception as e:  # a command the hand refused, a lost link: said in health
                self.errors += 1
                self.last_error = f"{type(e).__name__}: {e}"[:200]
            self._stop.wait(READ_PERIOD)

    def _start(self, c: GripperCmd) -> None:
        if self._future is not None and not self._future.wait(0):
            self.g.stop()  # the motion under way gives way to the newer command
        speed = c.speed if c.speed is not None else DEFAULT_SPEED
        if c.action == "close":
            assert c.force is not None  # (the wire refuses a close without one)
            if c.width is None:  # all the way, stopping on what is between the fingers
                width, inner = 0.0, 0.0
            else:
                width, inner = min(c.width, self.max_width), GRASP_EPSILON
            self._future = self.g.grasp_async(width, speed, c.force, epsilon_inner=min(width, inner),
                                              epsilon_outer=self.max_width)
        else:
            width = self.max_width if c.width is None else min(c.width, self.max_width)
            self._future = self.g.move_async(width, speed)
        self.cmd = c.cmd
