"""The simulated person's grasp button: pressing it as what they want of the fingers and
what they see of them say.

The runtime's grasp role (``docs/input.md``): a press closes the fingers when they are
open or hold nothing (and opens them again when they closed on nothing), and opening
them while they hold something takes the button held for a while (a tremor never drops
a cup). The person sees the fingers (the scene's ``gripper``: whether the newest command
closes them, and whether they hold something) and presses:

- to **close**, when the intent wants the fingers closed (the hand at the grip) and they
  are open; and again when they closed on nothing (a miss: that opens them);
- to **open**, held for :attr:`GraspButton.hold`, when the intent wants them open and
  they hold something; briefly when they are closed on nothing.

A press takes the stick's hand: the stick is let go while the button is down. After a
press the person waits to see what it did (``wait``) before pressing again.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

SHORT = 0.15
"""s the button is held down for a press."""
HOLD = 0.8
"""s it is held down to open fingers that hold something (the runtime asks for 0.5 s)."""
WAIT = 1.0
"""s after letting go of it before the person presses again (seeing what it did)."""


@dataclass
class GraspButton:
    """When the grasp button is down (see the module doc).

    Attributes
    ----------
    presses : int
        How often it was pressed.
    """

    short: float = SHORT
    hold: float = HOLD
    wait: float = WAIT
    presses: int = 0
    _down_until: float = -1.0
    _quiet_until: float = -1.0

    def down(self, t: float, want: str | None, scene: Mapping[str, Any]) -> bool:
        """Whether the button is down at ``t``, given what the intent wants of the fingers
        (``close``, ``open``, None) and the scene the person sees."""
        if t < self._down_until:
            return True
        if t < self._quiet_until:
            return False
        g = scene.get("gripper")
        if not isinstance(g, Mapping):
            return False
        closing, holding = bool(g.get("closing", False)), bool(g.get("grasped", False))
        length = 0.0
        if want == "close" and not closing:
            length = self.short
        elif closing and not holding and not g.get("moving", False):  # closed on nothing: open
            length = self.short
        elif want == "open" and holding:
            length = self.hold
        if length <= 0.0:
            return False
        self.presses += 1
        self._down_until = t + length
        self._quiet_until = t + length + self.wait
        return True
