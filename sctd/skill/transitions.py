"""FSM transitions (guarded edges between states), one class per kind.

Each kind reads its parameters from a skill file (``from_yaml``), writes them back
(``to_yaml``), summarises itself and says in the tick whether it fires (``fires``; a
button, an event, through ``pressed``; the gripper's reading, through the workspace's
``grasped``); :data:`TRANSITIONS` finds a kind by its ``type`` name. Guards carry a
hysteresis ``margin`` in their own unit.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Set
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from .. import se3
from .reader import Reader
from .registry import ByValue, Registry, summarised, unit_divisor
from .sketch import Arrow, Plane, Shape, Sphere
from .workspace import Workspace

Array = NDArray[np.float64]
Flat = se3.Flat

COMMON_KEYS = {"from", "to", "type", "margin"}  # allowed in every transition
MODE_BUTTON = 0  # the input message's mode switch (docs/wire-contract.md), a button transition's default
HYPERPLANE_SIZE = 0.2  # m: the side of a hyperplane guard as drawn
HYPERPLANE_ARROW = 0.05  # m: the arrow to the side it fires on


@dataclass(frozen=True, kw_only=True, eq=False)
class Transition(ByValue, ABC):
    """A guarded FSM edge from state ``source`` to state ``target``."""

    type: ClassVar[str]
    source: str
    target: str

    @classmethod
    @abstractmethod
    def from_yaml(cls, r: Reader, td: dict, path: str, source: str, target: str) -> Transition:
        """Read and validate this kind's parameters from the mapping ``td`` at ``path``
        (``from``, ``to`` and ``type`` already read)."""

    def to_yaml(self) -> dict[str, Any]:
        """The transition as the plain dict the loader reads (an entry of the FSM's
        ``transitions`` list: ``from``, ``to``, ``type``, then what :meth:`from_yaml`
        reads): every parameter, exactly."""
        return {"from": self.source, "to": self.target, "type": self.type, **self._parameters()}

    def summary(self) -> dict[str, Any]:
        """The transition as plain data (``sctd inspect --json``, the skill query)."""
        return summarised(self.to_yaml())

    def sketch(self) -> tuple[Shape, ...]:
        """Where the guard fires (:mod:`sctd.skill.sketch`, object frame): none for a
        kind that is no region of space (a time, a force, a button)."""
        return ()

    @abstractmethod
    def _parameters(self) -> dict[str, Any]:
        """This kind's own parameters for :meth:`to_yaml`."""

    @abstractmethod
    def fires(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> bool:
        """Whether the guard holds.

        Parameters
        ----------
        F : Flat
            Measured end-effector pose in the object frame.
        elapsed : float
            Seconds the source state has been active.
        force : ndarray, shape (3,), or None
            Measured force at the end-effector, in the object frame (N).
        ws : Workspace
        """

    def pressed(self, buttons: Set[int]) -> bool:
        """Whether the buttons pressed since the last update (rising edges) fire it: an
        event, acting however long the state has been active."""
        return False

    progress_step: ClassVar[float] = math.inf
    """How much :meth:`progress` must grow to count as a step towards firing (its unit;
    above the measurement's noise). Infinite for a kind that measures none."""

    def progress(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> float | None:
        """How close the guard is to firing, a number that grows towards it (the runtime's
        stuck detector, :class:`~sctd.skill.stuck.StuckDetector`); None for a kind whose
        way forward is not measured by the pose (a button). Same parameters as
        :meth:`fires`."""
        return None


TRANSITIONS: Registry[Transition] = Registry("transition")


@TRANSITIONS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class Hyperplane(Transition):
    """Fires when ``normal . p + offset > margin`` for the position p of ``frame`` in the
    object frame: the linear-SVM decision function of Algorithm 3 (positive side =
    ``target``), normalised to a unit ``normal`` (3,) so that it is a distance (m)."""

    type: ClassVar[str] = "hyperplane"
    frame: str = "ee"
    normal: Array
    offset: float = 0.0
    margin: float = 0.0
    _normal3: tuple[float, float, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_normal3", tuple(self.normal.tolist()))

    @classmethod
    def from_yaml(cls, r: Reader, td: dict, path: str, source: str, target: str) -> Hyperplane:
        r.known_keys(td, path, COMMON_KEYS | {"frame", "normal", "offset"})
        normal = r.vector(td.get("normal"), f"{path}.normal", 3)
        norm = float(np.linalg.norm(normal))
        if norm < 1e-12:
            raise r.fail(f"{path}.normal", "normal of zero length")
        offset = r.number(td.get("offset", 0.0), f"{path}.offset")
        norm = unit_divisor(norm)
        return cls(source=source, target=target,
                   frame=r.ee_frame_ref(td.get("frame", "ee"), f"{path}.frame"),
                   normal=normal / norm, offset=offset / norm,
                   margin=r.number(td.get("margin", 0.005), f"{path}.margin", 0.0))

    def _parameters(self) -> dict[str, Any]:
        return {"frame": self.frame, "normal": self.normal.tolist(), "offset": self.offset,
                "margin": self.margin}

    progress_step: ClassVar[float] = 0.002  # m

    def fires(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> bool:
        return self.progress(F, elapsed, force, ws) > self.margin

    def progress(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> float:
        """The signed distance (m) of the frame's position from the plane, positive on
        the ``target`` side: the SVM's decision value."""
        G = ws.frame_pose(F, self.frame)
        nx, ny, nz = self._normal3
        return nx * G[9] + ny * G[10] + nz * G[11] + self.offset

    def sketch(self) -> tuple[Shape, ...]:
        """The plane (through its point nearest the object's origin) and an arrow to
        the side where it fires."""
        p0 = -self.offset * self.normal
        return (Plane(f"{self.source} -> {self.target}: {self.frame} crosses", p0, self.normal,
                      HYPERPLANE_SIZE),
                Arrow(f"to {self.target}", p0, HYPERPLANE_ARROW * self.normal))


@TRANSITIONS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class Distance(Transition):
    """Fires when the distance from ``frame`` to ``point`` (3,; object frame) goes below
    ``threshold - margin`` (``direction == "below"``) or above ``threshold + margin``."""

    type: ClassVar[str] = "distance"
    frame: str = "ee"
    point: Array
    threshold: float
    direction: Literal["below", "above"] = "below"
    margin: float = 0.0
    _point3: tuple[float, float, float] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_point3", tuple(self.point.tolist()))

    @classmethod
    def from_yaml(cls, r: Reader, td: dict, path: str, source: str, target: str) -> Distance:
        r.known_keys(td, path, COMMON_KEYS | {"frame", "point", "below", "above"})
        if ("below" in td) == ("above" in td):
            raise r.fail(path, "a distance transition needs exactly one of below, above")
        direction = "below" if "below" in td else "above"
        return cls(source=source, target=target,
                   frame=r.ee_frame_ref(td.get("frame", "ee"), f"{path}.frame"),
                   point=r.vector(td.get("point", [0, 0, 0]), f"{path}.point", 3),
                   threshold=r.number(td[direction], f"{path}.{direction}", 0.0),
                   direction=direction,  # type: ignore[arg-type]
                   margin=r.number(td.get("margin", 0.005), f"{path}.margin", 0.0))

    def _parameters(self) -> dict[str, Any]:
        return {"frame": self.frame, "point": self.point.tolist(), self.direction: self.threshold,
                "margin": self.margin}

    progress_step: ClassVar[float] = 0.002  # m

    def fires(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> bool:
        d = self._distance(F, ws)
        if self.direction == "below":
            return d < self.threshold - self.margin
        return d > self.threshold + self.margin

    def progress(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> float:
        """The distance (m), negated for ``below``: it grows as the frame nears firing."""
        d = self._distance(F, ws)
        return -d if self.direction == "below" else d

    def sketch(self) -> tuple[Shape, ...]:
        """The sphere the frame's origin enters (``below``) or leaves (``above``)."""
        word = "within" if self.direction == "below" else "beyond"
        of = "the object's origin" if not np.any(self.point) else \
            "(" + ", ".join(f"{x:.3g}" for x in self.point.tolist()) + ")"
        return (Sphere(f"{self.source} -> {self.target}: {self.frame} {word} {self.threshold:g} m of {of}",
                       self.point, self.threshold),)

    def _distance(self, F: Flat, ws: Workspace) -> float:
        G = ws.frame_pose(F, self.frame)
        cx, cy, cz = self._point3
        dx, dy, dz = G[9] - cx, G[10] - cy, G[11] - cz
        return math.sqrt(dx * dx + dy * dy + dz * dz)


@TRANSITIONS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class Timeout(Transition):
    """Fires when the state has been active ``after`` seconds."""

    type: ClassVar[str] = "timeout"
    after: float

    @classmethod
    def from_yaml(cls, r: Reader, td: dict, path: str, source: str, target: str) -> Timeout:
        r.known_keys(td, path, COMMON_KEYS | {"after"})
        return cls(source=source, target=target, after=r.number(td.get("after"), f"{path}.after", 0.0))

    def _parameters(self) -> dict[str, Any]:
        return {"after": self.after}

    progress_step: ClassVar[float] = 0.0  # s: time alone carries it forward

    def fires(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> bool:
        return elapsed >= self.after

    def progress(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> float:
        """The time in the state (s): a timeout is always on its way."""
        return elapsed


@TRANSITIONS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class Force(Transition):
    """Fires when the measured force, along the unit ``axis`` (3,; object frame) or its
    norm without one, exceeds ``above + margin`` newtons."""

    type: ClassVar[str] = "force"
    above: float
    axis: Array | None = None
    margin: float = 0.0

    @classmethod
    def from_yaml(cls, r: Reader, td: dict, path: str, source: str, target: str) -> Force:
        r.known_keys(td, path, COMMON_KEYS | {"above", "axis"})
        axis = td.get("axis")
        return cls(source=source, target=target,
                   above=r.number(td.get("above"), f"{path}.above", 0.0),
                   axis=None if axis is None else r.vector(axis, f"{path}.axis", 3, unit=True),
                   margin=r.number(td.get("margin", 1.0), f"{path}.margin", 0.0))

    def _parameters(self) -> dict[str, Any]:
        out: dict[str, Any] = {"above": self.above}
        if self.axis is not None:
            out["axis"] = self.axis.tolist()
        return out | {"margin": self.margin}

    progress_step: ClassVar[float] = 0.5  # N

    def fires(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> bool:
        f = self.progress(F, elapsed, force, ws)
        return f is not None and f > self.above + self.margin

    def progress(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> float | None:
        """The measured force along the axis, or its norm (N); None without a force."""
        if force is None:
            return None
        return float(np.dot(force, self.axis)) if self.axis is not None else float(np.linalg.norm(force))


@TRANSITIONS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class Button(Transition):
    """Fires when input button ``button`` (its index in the input message) is pressed."""

    type: ClassVar[str] = "button"
    button: int = MODE_BUTTON

    @classmethod
    def from_yaml(cls, r: Reader, td: dict, path: str, source: str, target: str) -> Button:
        r.known_keys(td, path, COMMON_KEYS | {"button"})
        return cls(source=source, target=target,
                   button=r.integer(td.get("button", MODE_BUTTON), f"{path}.button", 0))

    def _parameters(self) -> dict[str, Any]:
        return {"button": self.button}

    def fires(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> bool:
        return False

    def pressed(self, buttons: Set[int]) -> bool:
        return self.button in buttons


@TRANSITIONS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class Gripper(Transition):
    """Fires when the newest robot state's gripper reading says the fingers hold
    something (``grasped: true``) or hold nothing (``grasped: false``). Never fires when
    the robot reports no gripper or its state is stale (the workspace's ``grasped`` is
    None then): an unknown hand neither holds nor lets go."""

    type: ClassVar[str] = "gripper"
    grasped: bool = True

    @classmethod
    def from_yaml(cls, r: Reader, td: dict, path: str, source: str, target: str) -> Gripper:
        r.known_keys(td, path, COMMON_KEYS | {"grasped"})
        if "grasped" not in td:
            raise r.fail(f"{path}.grasped", "a gripper transition needs grasped: true or false")
        return cls(source=source, target=target, grasped=r.boolean(td["grasped"], f"{path}.grasped"))

    def _parameters(self) -> dict[str, Any]:
        return {"grasped": self.grasped}

    def fires(self, F: Flat, elapsed: float, force: Array | None, ws: Workspace) -> bool:
        return ws.grasped is self.grasped
