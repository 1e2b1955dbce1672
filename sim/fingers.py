"""The simulated hand's two fingers (pure logic): a parallel gripper that opens and
closes at a bounded speed, stops on what lies between them and says whether it holds
something.

Commands are the wire's (:class:`sctd.wire.codec.GripperCmd`): ``open`` (to ``width``,
else all the way), ``close`` (until they meet something, squeezing at most ``force``),
``width`` (to ``width``, no grasp). Each command number is carried out once; a repeat
changes nothing. Nothing here opens on its own: without a command the fingers stay as
they are, holding what they hold. What stops them is the scene's: an item between them
calls :meth:`block` at its width every step while they close on it.
"""

from __future__ import annotations

from sctd.wire.codec import GripperCmd, GripperReading

MAX_WIDTH = 0.08
"""m: the widest the fingers open (a Franka Hand's 80 mm)."""
SPEED = 0.05
"""m/s: how fast the fingers move when a command says no speed."""
MAX_SPEED = 0.1
"""m/s: the fastest they move (a Franka Hand's); a faster command is cut to it."""
MAX_FORCE = 70.0
"""N: the most they squeeze (a Franka Hand's continuous force); a larger bound is cut to it."""


class Fingers:
    """Two fingers closing along the hand's y axis (see the module doc).

    Attributes
    ----------
    width : float
        m between the fingertips now.
    target : float
        m they move to.
    closing : bool
        The newest command closes them (a grasp).
    force : float
        N they squeeze with while they hold something.
    cmd : int
        The newest command number carried out or under way (-1: none).
    """

    def __init__(self, max_width: float = MAX_WIDTH, speed: float = SPEED, width: float | None = None):
        self.max_width, self.speed = max_width, speed
        self._start = max_width if width is None else width
        self.cmd = -1
        self.reset()

    def reset(self) -> None:
        """Open, as at the start (a scene's reset). The newest command's number is kept: a
        sender's repeats of it after the reset change nothing."""
        self.width = self.target = self._start
        self.closing = False
        self.force = 0.0
        self._speed = self.speed
        self._blocked: float | None = None  # the width something stopped them at this step

    def command(self, c: GripperCmd) -> bool:
        """Take command ``c`` (once per number); whether it was new."""
        if c.cmd == self.cmd:
            return False
        self.cmd = c.cmd
        self._speed = min(MAX_SPEED, c.speed) if c.speed is not None else self.speed
        if c.action == "close":
            self.closing, self.force = True, min(MAX_FORCE, c.force if c.force is not None else MAX_FORCE)
            self.target = 0.0 if c.width is None else min(c.width, self.max_width)
        else:
            self.closing, self.force = False, 0.0
            self.target = self.max_width if c.width is None else min(c.width, self.max_width)
        return True

    def block(self, width: float) -> None:
        """Something ``width`` wide lies between them and they close on it: they stop there."""
        self._blocked = width
        self.width = max(self.width, width)

    def advance(self, dt: float) -> None:
        """Move towards the target for ``dt`` (before the scene says what blocks them)."""
        self._blocked = None
        step = self._speed * dt
        self.width = min(self.target, self.width + step) if self.width < self.target else \
            max(self.target, self.width - step)

    def reading(self) -> GripperReading:
        """The state's ``gripper``: width, whether they hold something, whether they move."""
        holding = self._blocked is not None and self.closing
        moving = not holding and abs(self.width - self.target) > 1e-5
        return GripperReading(self.width, holding, moving, self.cmd)


class MirroredFingers(Fingers):
    """Fingers that show a real gripper's readings (``sctd robot NAME`` beside an arm that
    is not ours): the scene judges what the hand takes from what the gripper reports
    (:meth:`mirror`), and moves nothing on its own. Holding something (``grasped``), they
    close on it with the squeeze of an arm's hand that holds it (:data:`MAX_FORCE`)."""

    def mirror(self, width: float, grasped: bool) -> None:
        """The gripper's newest reading: its ``width`` (m) and whether it holds something."""
        self.width = self.target = min(max(0.0, float(width)), self.max_width)
        self.closing = bool(grasped)
        self.force = MAX_FORCE if grasped else 0.0

    def advance(self, dt: float) -> None:
        """Nothing moves but the real fingers (:meth:`mirror`)."""
        self._blocked = None

    def block(self, width: float) -> None:
        """What the scene says lies between them (the width stays the reading's)."""
        self._blocked = width
