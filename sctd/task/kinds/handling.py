"""Taking an item and putting it down: the ``grasp`` and ``place`` intent steps.

``grasp`` (an item, the squeeze ``force``, how high it is ``lift``-ed clear): the hand
comes to a point ``approach`` back from where a person takes the item (its axis at its
``grip`` height), along the hand's own x as it was when the step began, then in
onto it with the fingers across its axis, closes them, and lifts it until its base is
``lift`` above where it rested. Done once it is held and lifted; it begins again while
the item is not held.

``place`` (the item, ``onto`` a support, ``at`` a point of its top): the item is carried
upright to ``hover`` over that point (over the rim of a support with one), lowered until
the top pushes back on it, let go, and the hand backs away ``clear`` along its own x
until it is that far from the item's axis. Done once the item is let go and the hand is
clear; back to the step before (a grasp) while the item is neither held nor let go here.

What a simulated person does for each (:class:`GraspMind`, :class:`PlaceMind`) is part of
the kind.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..model import Outcome, Scene, Step
from .base import Array, Floor, Leg, Person, Run, Sight, StepKind, StepMind, Want
from .pickable import Item, Support, facet_of

if TYPE_CHECKING:  # (typing only)
    from ..model import Task

UP = np.array([0.0, 0.0, 1.0])
IN_REACH = 0.015  # m: at the point before the grasp, near enough to come in
STRAY = 0.03  # m: off the line in by this much, the hand goes back to the point before
AT_GRIP = (0.004, 0.004, 0.012)  # m: the grip point this near (hand's x, y, z) to close the fingers
SQUARE = math.sin(math.radians(8.0))  # the fingers this square to the axis need no turning
STILL = 0.01  # m/s: the hand this slow to close the fingers
TOUCH = 1.0  # N: the top pushes back this hard on an item being lowered: it is down
LOWER_SPEED = 0.02  # m/s: lowering onto the top
PLACED = 0.006  # m: lowered to within this of the top, it is down as well
# how a person's demonstrations vary (sctd teach)
TURN_AWAY = 0.15  # rad: the hand's yaw about the vertical, either way, as it comes in
HIGHER = 0.02  # m: lifted or carried up to this much higher than the step says
OFF_SPOT = 0.01  # m: put down up to this far from the spot, each way
MISS = 0.03  # m: a mistaken grasp closes this far beside the item's axis
SLOW = 0.4  # coming onto a grip or down onto a top: this share of the reach speed


def _f(x: float) -> float:
    return float(x)


def _item(r: Any, v: Any, path: str, scene: Scene) -> str:
    name = r.name(v, path)
    if name not in scene.with_facet("item"):
        items = ", ".join(scene.with_facet("item")) or "none"
        raise r.fail(path, f"{name!r} is no item (items: {items})")
    return name


def _saturate(v: Array, limit: float) -> Array:
    n = float(np.linalg.norm(v))
    return v if n <= limit else v * (limit / n)


def _square(T_world_ee: Array, axis: Array, gain: float) -> tuple[Array, float]:
    """The angular velocity that turns the fingers' line (the hand's y) square to the item's
    ``axis``, and how far from square it is (the sine of the angle off)."""
    y = T_world_ee[:3, 1]
    c = float(y @ axis)
    return -gain * c * np.cross(y, axis), abs(c)


def _ahead(T_world_ee: Array, to_grip: Array) -> Array:
    """The horizontal direction a hand comes in along: its own x (the fingers open across
    the way in), or the way to the grip where its x points up or down."""
    for d in (T_world_ee[:3, 0].copy(), to_grip.copy()):
        d[2] = 0.0
        n = float(np.linalg.norm(d))
        if n > 0.3:
            return d / n
    return np.array([1.0, 0.0, 0.0])


def _pose(R: Array, p: Array) -> Array:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def _yawed(R: Array, rng: np.random.Generator, spread: float) -> Array:
    """``R`` turned about the vertical by a yaw drawn from [-spread, spread]."""
    a = float(rng.uniform(-spread, spread))
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ R


def take_legs(R: Array, grip: Array, approach: float, force: float, held: str, rng: np.random.Generator,
              mistake: bool) -> list[Leg]:
    """The legs of taking something at ``grip`` (world) with the hand turned ``R``: to the
    point ``approach`` back along its x, slowly in (beside it along its y, for a mistake),
    close with ``force`` and wait until ``held`` is true."""
    ahead = _ahead(_pose(R, grip), np.zeros(3))
    at = grip + (MISS * R[:, 1] if mistake else 0.0)
    return [Leg(_pose(R, at - approach * ahead)),
            Leg(_pose(R, at), SLOW, "close", force, (held, True))]


def _weights(person: Person, turning: bool) -> Array:
    W = np.zeros((6, 6))
    W[:3, :3] = np.eye(3) / person.v_max
    W[3:, 3:] = np.eye(3) / person.w_max if turning else np.eye(3) * person.free_weight
    return W


@dataclass(frozen=True)
class GraspStep(StepKind):
    """Take ``item`` (see the module doc).

    Attributes
    ----------
    item : str
    force : float
        N the fingers squeeze with.
    lift : float
        m its base is lifted above where it rested.
    approach : float
        m back from the grip point the hand comes in from.
    """

    key = "grasp"
    grips = True

    item: str
    force: float
    lift: float = 0.05
    approach: float = 0.08

    @classmethod
    def read(cls, r: Any, v: Any, path: str, scene: Scene, outcome: Outcome,
             before: tuple[Step, ...]) -> GraspStep:
        d = r.fields(v, path, {"item", "force"}, {"lift", "approach"})
        return cls(_item(r, d["item"], f"{path}.item", scene), r.positive(d["force"], f"{path}.force"),
                   r.positive(d.get("lift", 0.05), f"{path}.lift"),
                   r.positive(d.get("approach", 0.08), f"{path}.approach"))

    def to_yaml(self, scene: Scene) -> dict[str, Any]:
        return {"item": self.item, "force": _f(self.force), "lift": _f(self.lift),
                "approach": _f(self.approach)}

    def frame(self) -> str:
        return "hand"

    def mind(self, run: Run, index: int) -> StepMind:
        return GraspMind(self, facet_of(run.scene, self.item, Item), run.person)

    def floor_path(self, task: Task, before: tuple[Floor, ...]) -> Floor:
        """To the grip, then the lift."""
        scene = task.scene
        T = scene.bodies[self.item].T_world
        grip = T[:3, 3] + facet_of(scene, self.item, Item).grip * T[:3, 2]
        return Floor((grip, grip + self.lift * UP), 0.0)

    def legs(self, scene: Scene, poses: Mapping[str, Array], T_world_ee: Array, rng: np.random.Generator,
             mistake: bool = False) -> list[Leg]:
        """To it, in, close until it is held, lift it (up to :data:`HIGHER` more)."""
        item = facet_of(scene, self.item, Item)
        T = poses[self.item]
        grip = T[:3, 3] + item.grip * T[:3, 2]
        R = _yawed(T_world_ee[:3, :3], rng, TURN_AWAY)
        up = grip + (self.lift + float(rng.uniform(0.0, HIGHER))) * UP
        return [*take_legs(R, grip, self.approach, self.force, f"{self.item}.held", rng, mistake),
                Leg(_pose(R, up), SLOW)]


class GraspMind(StepMind):
    """A person taking an item: to the point before it, in, close, lift (the module doc)."""

    def __init__(self, step: GraspStep, item: Item, person: Person):
        self.step, self.item, self.person = step, item, person
        self._from: Array | None = None  # the horizontal direction the hand comes in along
        self._in = False  # coming in along it (past the point before the grip)

    def _grip(self, sight: Sight) -> tuple[Array, Array]:
        T = sight.objects[self.step.item]
        return T[:3, 3] + self.item.grip * T[:3, 2], T[:3, 2]

    def move(self, sight: Sight) -> int:
        r = sight.readings
        held = bool(r.get(f"{self.step.item}.held", False))
        return 1 if held and float(r.get(f"{self.step.item}.lifted", 0.0)) >= self.step.lift else 0

    def _goal(self, sight: Sight) -> tuple[Array, bool]:
        """Where the hand goes now, and whether it is at the grip point (to close)."""
        grip, _ = self._grip(sight)
        p = sight.T_world_ee[:3, 3]
        if bool(sight.readings.get(f"{self.step.item}.held", False)):  # up, a little past the lift
            self._from, self._in = None, False
            lifted = float(sight.readings.get(f"{self.step.item}.lifted", 0.0))
            return p + UP * max(0.0, self.step.lift + 0.01 - lifted), False
        if self._from is None:
            self._from = _ahead(sight.T_world_ee, grip - p)
        before = grip - self.step.approach * self._from
        off = grip - p
        lateral = off - float(off @ self._from) * self._from
        if self._in and float(np.linalg.norm(lateral)) > STRAY:  # off the line in: back out first
            self._in = False
        if not self._in and float(np.linalg.norm(before - p)) < IN_REACH:
            self._in = True
        if not self._in:
            return before, False
        e = sight.T_world_ee[:3, :3].T @ (grip - p)
        return grip, all(abs(float(x)) <= tol for x, tol in zip(e, AT_GRIP, strict=True))

    def error(self, sight: Sight) -> float:
        grip, _ = self._grip(sight)
        lifted = float(sight.readings.get(f"{self.step.item}.lifted", 0.0))
        if bool(sight.readings.get(f"{self.step.item}.held", False)):
            return max(0.0, self.step.lift - lifted)
        return float(np.linalg.norm(grip - sight.T_world_ee[:3, 3])) + self.step.lift

    def want(self, sight: Sight) -> Want:
        p = sight.T_world_ee[:3, 3]
        goal, at = self._goal(sight)
        _, axis = self._grip(sight)
        w, off = _square(sight.T_world_ee, axis, self.person.gain)
        held = bool(sight.readings.get(f"{self.step.item}.held", False))
        turning = off > SQUARE and not held
        v = _saturate(self.person.gain * (goal - p), self.person.v_max)
        twist = np.concatenate([v, _saturate(w, self.person.w_max) if turning else np.zeros(3)])
        grip = "close" if (at and off <= 2 * SQUARE) or held else None
        return Want(twist, _weights(self.person, turning), grip)


@dataclass(frozen=True)
class PlaceStep(StepKind):
    """Put ``item`` down ``onto`` a support (see the module doc).

    Attributes
    ----------
    item, onto : str
    at : tuple of 2 floats
        Where on the support's top, in its frame, m.
    hover : float
        m over the top (over the rim) it is carried to before it is lowered.
    clear : float
        m the hand backs away once it let go.
    """

    key = "place"
    grips = True

    item: str
    onto: str
    at: tuple[float, float] = (0.0, 0.0)
    hover: float = 0.05
    clear: float = 0.06

    @classmethod
    def read(cls, r: Any, v: Any, path: str, scene: Scene, outcome: Outcome,
             before: tuple[Step, ...]) -> PlaceStep:
        d = r.fields(v, path, {"item", "onto"}, {"at", "hover", "clear"})
        item = _item(r, d["item"], f"{path}.item", scene)
        onto = r.name(d["onto"], f"{path}.onto")
        sup = scene.bodies[onto].facets.get("support") if onto in scene.bodies else None
        if not isinstance(sup, Support):
            raise r.fail(f"{path}.onto", f"{onto!r} is no support (supports: "
                                         f"{', '.join(scene.with_facet('support')) or 'none'})")
        at = tuple(r.vector(d.get("at", [0.0, 0.0]), f"{path}.at", 2).tolist())
        radius = facet_of(scene, item, Item).radius
        if not sup.inside(np.array([*at, 0.0]), radius):
            raise r.fail(f"{path}.at", f"[{at[0]}, {at[1]}] is not on the top of {onto!r} with the item's "
                                       f"radius {radius:g} m to spare (its top: {sup.size[0]:g} x "
                                       f"{sup.size[1]:g} m)")
        return cls(item, onto, (at[0], at[1]), r.positive(d.get("hover", 0.05), f"{path}.hover"),
                   r.positive(d.get("clear", 0.06), f"{path}.clear"))

    def to_yaml(self, scene: Scene) -> dict[str, Any]:
        return {"item": self.item, "onto": self.onto, "at": [_f(self.at[0]), _f(self.at[1])],
                "hover": _f(self.hover), "clear": _f(self.clear)}

    def frame(self) -> str:
        return self.item

    def mind(self, run: Run, index: int) -> StepMind:
        return PlaceMind(self, facet_of(run.scene, self.item, Item), facet_of(run.scene, self.onto, Support),
                         run.person)

    def floor_path(self, task: Task, before: tuple[Floor, ...]) -> Floor:
        """To where the hand holds the item down on the spot, then ``clear`` back."""
        scene = task.scene
        S = scene.bodies[self.onto].T_world
        grip = facet_of(scene, self.item, Item).grip
        down = S[:3, :3] @ np.array([self.at[0], self.at[1], grip]) + S[:3, 3]
        back = down - self.clear * _ahead(scene.start.T_world, np.zeros(3))
        return Floor((down, back), 0.0)

    def legs(self, scene: Scene, poses: Mapping[str, Array], T_world_ee: Array, rng: np.random.Generator,
             mistake: bool = False) -> list[Leg]:
        """Up to the carrying height, over the spot (up to :data:`OFF_SPOT` off it), down
        onto the top, open until it is let go, back along the hand's x."""
        item, sup = facet_of(scene, self.item, Item), facet_of(scene, self.onto, Support)
        S, R = poses[self.onto], T_world_ee[:3, :3]
        off = rng.uniform(-OFF_SPOT, OFF_SPOT, 2)
        spot = S[:3, :3] @ np.array([self.at[0] + off[0], self.at[1] + off[1], 0.0]) + S[:3, 3]
        high = float(spot[2]) + sup.rim + self.hover + float(rng.uniform(0.0, HIGHER)) + item.grip
        here = T_world_ee[:3, 3]
        down = spot + (item.grip + 0.002) * S[:3, 2]
        ahead = _ahead(T_world_ee, np.zeros(3))
        return [Leg(_pose(R, np.array([here[0], here[1], max(high, float(here[2]))]))),
                Leg(_pose(R, np.array([down[0], down[1], max(high, float(here[2]))]))),
                Leg(_pose(R, down), SLOW, "open", None, (f"{self.item}.held", False)),
                Leg(_pose(R, down - self.clear * ahead + 0.01 * UP), SLOW)]


class PlaceMind(StepMind):
    """A person putting an item down: over the spot, down, let go, back away (the module doc)."""

    def __init__(self, step: PlaceStep, item: Item, support: Support, person: Person):
        self.step, self.item, self.support, self.person = step, item, support, person
        self._released = False

    def _spot(self, sight: Sight) -> tuple[Array, Array]:
        """The point of the top it goes to (world), and the top's normal."""
        S = sight.objects[self.step.onto]
        return S[:3, :3] @ np.array([*self.step.at, 0.0]) + S[:3, 3], S[:3, 2]

    def _state(self, sight: Sight) -> str:
        r, n = sight.readings, self.step.item
        if bool(r.get(f"{n}.held", False)):
            self._released = False
            return "carry"
        if self._released or (bool(r.get(f"{n}.resting", False)) and self._on_top(sight)):
            self._released = True
            return "away"
        return "lost"

    def _on_top(self, sight: Sight) -> bool:
        """Whether the item stands on the support it is to go onto (its base on the top)."""
        S = sight.objects[self.step.onto]
        p = S[:3, :3].T @ (sight.objects[self.step.item][:3, 3] - S[:3, 3])
        return abs(float(p[2])) < 0.005 and self.support.inside(p)

    def _clear_of(self, sight: Sight) -> float:
        """How far the hand is from the item's axis, m."""
        T = sight.objects[self.step.item]
        d = sight.T_world_ee[:3, 3] - T[:3, 3]
        return float(np.linalg.norm(d - float(d @ T[:3, 2]) * T[:3, 2]))

    def move(self, sight: Sight) -> int:
        state = self._state(sight)
        if state == "lost":
            return -1
        return 1 if state == "away" and self._clear_of(sight) >= self.step.clear else 0

    def error(self, sight: Sight) -> float:
        spot, _ = self._spot(sight)
        base = sight.objects[self.step.item][:3, 3]
        state = self._state(sight)
        if state == "away":
            return max(0.0, self.step.clear - self._clear_of(sight))
        return float(np.linalg.norm(base - spot)) + self.step.clear

    def want(self, sight: Sight) -> Want:
        state = self._state(sight)
        p = sight.T_world_ee[:3, 3]
        if state == "away":
            back = -sight.T_world_ee[:3, 0].copy()
            back[2] = 0.0
            n = float(np.linalg.norm(back))
            v = self.person.v_max * 0.5 * (back / n if n > 1e-6 else np.zeros(3)) + 0.02 * UP
            return Want(np.concatenate([v, np.zeros(3)]), _weights(self.person, False), "open")
        if state == "lost":
            return Want(np.zeros(6), _weights(self.person, False), None)
        return self._carry(sight, p)

    def _carry(self, sight: Sight, p: Array) -> Want:
        """Over the spot, then down onto it, then let go."""
        T = sight.objects[self.step.item]
        base = T[:3, 3]
        spot, normal = self._spot(sight)
        horizontal = (spot - base) - float((spot - base) @ normal) * normal
        height = float((base - spot) @ normal)
        pushed = float(sight.readings.get(f"{self.step.item}.force", 0.0)) >= TOUCH
        down = pushed or height < PLACED
        off = float(np.linalg.norm(horizontal))
        grip = "open" if down and off < 0.5 * self.item.radius else "close"
        above = self.step.hover + self.support.rim  # how high it is carried over the top
        if off > 0.01 and height < self.support.rim + 0.01:  # up first, over the rim
            v = _saturate(self.person.gain * (above - height) * normal, self.person.v_max)
        elif off > 0.01:  # over the spot, at least that high
            v = _saturate(self.person.gain * (horizontal + max(0.0, above - height) * normal),
                          self.person.v_max)
        elif down:
            v = np.zeros(3)
        else:  # down onto it
            v = _saturate(self.person.gain * horizontal, self.person.v_max) - LOWER_SPEED * normal
        tilt_w = self._upright(T)
        turning = float(np.linalg.norm(tilt_w)) > 0.0
        w = _saturate(tilt_w, self.person.w_max)
        v_ee = v - np.cross(w, base - p)
        return Want(np.concatenate([v_ee, w]), _weights(self.person, turning), grip)

    def _upright(self, T: Array) -> Array:
        """The angular velocity that brings the item's axis upright, where it leans past 5 deg."""
        z = T[:3, 2]
        tilt = math.acos(max(-1.0, min(1.0, float(z[2]))))
        if tilt < math.radians(5.0):
            return np.zeros(3)
        back = np.cross(z, UP)
        n = float(np.linalg.norm(back))
        return back / n * self.person.gain * tilt if n > 1e-9 else np.zeros(3)
