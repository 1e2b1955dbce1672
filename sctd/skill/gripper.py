"""What a skill state asks of the gripper when it is entered (``gripper:`` of a state).

A state may say what the hand's fingers do at its entry::

    states:
      grasp:
        gripper: {action: close, force: 20}      # squeeze at most 20 N
      release:
        gripper: {action: open}                  # all the way (or to ``width``)
      pre_shape:
        gripper: {action: width, width: 0.04}    # to 4 cm, not a grasp

:class:`GripperAction` holds it, reads it (:meth:`GripperAction.from_yaml`, errors
naming the field) and writes it back (:meth:`GripperAction.to_yaml`). The skill says
what; the runtime numbers the command and publishes it on ``sctd/<robot>/gripper``
(docs/wire-contract.md, "The gripper"): the pure core does no I/O.

The ranges are the wire contract's (``sctd.wire.codec``: ``MAX_GRIPPER_WIDTH``, ...;
the wire sits above this package, so the numbers are repeated here and a test holds the
two together), so a skill can never ask for a command a robot would refuse.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .reader import Reader
from .registry import ByValue

GRIPPER_ACTIONS = ("open", "close", "width")
MAX_WIDTH = 0.5  # m
MAX_FORCE = 1000.0  # N
MAX_SPEED = 1.0  # m/s
KEYS = {"action", "width", "force", "speed"}


@dataclass(frozen=True, kw_only=True, eq=False)
class GripperAction(ByValue):
    """A gripper command a state gives at its entry.

    Parameters
    ----------
    action : str
        ``open`` (to ``width``, else all the way), ``close`` (until the fingers meet
        something, squeezing at most ``force`` N, or down to ``width``), ``width`` (to
        ``width``, not a grasp).
    width : float or None
        m, in [0, :data:`MAX_WIDTH`]; required for ``width``.
    force : float or None
        N, in (0, :data:`MAX_FORCE`]; required for ``close``.
    speed : float or None
        m/s, in (0, :data:`MAX_SPEED`]; the robot's own speed without one.
    """

    action: str
    width: float | None = None
    force: float | None = None
    speed: float | None = None

    @classmethod
    def from_yaml(cls, r: Reader, d: Any, path: str) -> GripperAction:
        """Read and check the mapping ``d`` at ``path`` (``states.<name>.gripper``)."""
        d = r.mapping(d, path)
        r.known_keys(d, path, KEYS)
        action = r.choice(d.get("action"), f"{path}.action", GRIPPER_ACTIONS)
        width = None if d.get("width") is None else r.number(d["width"], f"{path}.width", 0.0, MAX_WIDTH)
        force = None if d.get("force") is None else r.number(d["force"], f"{path}.force", 0.0, MAX_FORCE,
                                                             lo_open=True)
        speed = None if d.get("speed") is None else r.number(d["speed"], f"{path}.speed", 0.0, MAX_SPEED,
                                                             lo_open=True)
        if action == "close" and force is None:
            raise r.fail(f"{path}.force", "action close needs a force bound (N): the most the fingers "
                                          "squeeze")
        if action == "width" and width is None:
            raise r.fail(f"{path}.width", "action width needs a width (m)")
        return cls(action=action, width=width, force=force, speed=speed)

    def to_yaml(self) -> dict[str, Any]:
        """The mapping :meth:`from_yaml` reads: the action, then what is set."""
        out: dict[str, Any] = {"action": self.action}
        for key in ("width", "force", "speed"):
            value = getattr(self, key)
            if value is not None:
                out[key] = value
        return out
