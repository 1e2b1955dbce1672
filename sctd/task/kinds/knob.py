"""A handle turned in the hand about its own axis (a tap, a stove's knob): the ``knob``
facet of a body and the ``turn`` intent step.

A **knob** is a cylinder standing on its body's origin along the body's z (``radius``,
``height``), turning about that axis from 0 to ``travel`` (rad), against Coulomb
``friction`` (N m) and stiff end stops. The fingers take it as they take an item (their
line across its axis, its axis between them, on its side); held, it turns with the
hand's turning about its axis, the fingers' grasp holds the hand's middle on the axis
with a spring (``stiffness``, ``damping``) and slips off when pulled ``release`` from it,
and the knob stays where it was turned when let go. Its published frame stays at 0, as a
joint's handle does. It reports its ``position`` (rad), whether it is ``held``, how often
it was grasped (``grasps``), the furthest it was turned (``max_position``) and the
torque about its axis it resists the hand with (``torque``, N m).

A **turn** (``knob``, the squeeze ``force``, ``overshoot``, ``approach``, ``clear``): the
hand comes to a point ``approach`` back from the knob's grip (along its own x as it was
when the step began), in onto it, closes, turns it to the position the task's
``done`` asks of ``<knob>.position`` plus ``overshoot``, lets go and backs away until it
is ``clear`` of the axis. Done once the knob is there, let go, and the hand clear; a knob
let go short of it is taken again.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from sctd import se3

from ..judge import thresholds
from ..model import Outcome, Scene, Step
from .base import (
    Array,
    Facet,
    FacetPhysics,
    Floor,
    Leg,
    Person,
    Run,
    Shape,
    Sight,
    StepKind,
    StepMind,
    Want,
    World,
)
from .handling import (
    AT_GRIP,
    IN_REACH,
    SLOW,
    STRAY,
    TURN_AWAY,
    _ahead,
    _pose,
    _saturate,
    _square,
    _weights,
    _yawed,
    take_legs,
)
from .pickable import FREE, across_fingers, facet_of

if TYPE_CHECKING:  # (typing only)
    from ..model import Task

STOP = 20.0  # N m/rad: an end stop's stiffness
SHAFT = 5.0  # N m/rad: the knob's shaft against tilting it
SPIN = 0.05  # rad/s over which the friction builds up (tanh)
THERE = math.radians(1.5)  # a person sees the knob turned to where they want it this near


def _f(x: float) -> float:
    return float(x)


@dataclass(frozen=True)
class Knob(Facet):
    """A handle turned in the hand about its own axis (see the module doc).

    Attributes
    ----------
    radius, height : float
        m; the fingers take it at ``2 radius``.
    travel : float
        rad from 0 to its end stop.
    friction : float
        N m.
    grip : float
        Height along its axis a person takes it at, m.
    aim : float
        m: the fingers take it with its axis within this of their middle, along the hand's x.
    stiffness, damping, release : float
        The grasp's spring (N/m), damper (N s/m), and how far pulled from the axis it slips off (m).
    """

    key = "knob"
    order = 30
    quantities = ("position", "held", "grasps", "max_position", "torque")
    flags = ("held",)
    angular = ("position", "max_position")

    radius: float
    height: float
    travel: float
    friction: float
    grip: float
    aim: float = 0.01
    stiffness: float = 2000.0
    damping: float = 60.0
    release: float = 0.03

    @classmethod
    def read(cls, r: Any, v: Any, path: str) -> Knob:
        d = r.fields(v, path, {"radius", "height", "travel", "friction"},
                     {"grip", "aim", "stiffness", "damping", "release"})
        height = r.positive(d["height"], f"{path}.height")
        grip = r.number(d.get("grip", height / 2), f"{path}.grip")
        if not 0.2 * height <= grip <= height:
            raise r.fail(f"{path}.grip", f"expected a height on its side, {0.2 * height:.3f}-{height:.3f} m "
                                         f"along its axis, got {grip}")
        return cls(r.positive(d["radius"], f"{path}.radius"), height,
                   r.angle(d["travel"], f"{path}.travel", lo=0.0, hi=2 * math.pi, lo_open=True),
                   r.nonneg(d["friction"], f"{path}.friction"), grip,
                   r.positive(d.get("aim", 0.01), f"{path}.aim"),
                   r.positive(d.get("stiffness", 2000.0), f"{path}.stiffness"),
                   r.nonneg(d.get("damping", 60.0), f"{path}.damping"),
                   r.positive(d.get("release", 0.03), f"{path}.release"))

    def to_yaml(self) -> dict[str, Any]:
        out: dict[str, Any] = {"radius": _f(self.radius), "height": _f(self.height),
                               "travel": _f(self.travel), "friction": _f(self.friction),
                               "grip": _f(self.grip)}
        defaults = Knob(1.0, 1.0, 1.0, 0.0, 0.5)
        for name in ("aim", "stiffness", "damping", "release"):
            if getattr(self, name) != getattr(defaults, name):
                out[name] = _f(getattr(self, name))
        return out

    def physics(self, body: str, scene: Scene) -> FacetPhysics:
        return _KnobPhysics(body, self)

    def shapes(self) -> list[Shape]:
        pointer = se3.transform_from_rt(np.eye(3), [self.radius / 2, 0.0, self.height + 0.002])
        return [Shape("cylinder", (self.radius, self.radius, self.height),
                      se3.transform_from_rt(np.eye(3), [0.0, 0.0, self.height / 2]), (0.85, 0.85, 0.85)),
                Shape("box", (self.radius, 0.004, 0.004), pointer, (0.8, 0.2, 0.2))]


class _KnobPhysics(FacetPhysics):
    """A knob turned with the hand that holds it (the module doc)."""

    def __init__(self, body: str, knob: Knob):
        self.body, self.knob = body, knob
        self.reset(World(np.eye(4), np.zeros(6), {}))

    def reset(self, world: World) -> None:
        self.position = self.max_position = self.torque = 0.0
        self.grasps = 0
        self._grasp: tuple[Array, float, Array] | None = None  # hand's rotation, position, point at the grasp

    @property
    def held(self) -> bool:
        return self._grasp is not None

    def step(self, world: World, dt: float) -> Array:
        f, k = world.fingers, self.knob
        T = world.poses[self.body]
        if self._grasp is None:
            if f is not None and f.closing and f.width <= 2 * k.radius + FREE and \
                    across_fingers(world.T_world_ee, T, f, k.radius, (0.2 * k.height, k.height), k.aim):
                f.block(2 * k.radius)
                self._grasp = (world.T_world_ee[:3, :3].copy(), self.position, world.T_world_ee[:3, 3].copy())
                self.grasps += 1
            self.torque = 0.0
            return np.zeros(6)
        if f is None or (not f.closing and f.width > 2 * k.radius + FREE):
            self._grasp = None  # (let go: it stays where it was turned)
            self.torque = 0.0
            return np.zeros(6)
        if f.closing:
            f.block(2 * k.radius)
        return self._turned(world)

    def _turned(self, world: World) -> Array:
        """The knob turned with the hand; the grasp's spring and the knob's torques on it."""
        assert self._grasp is not None
        k, axis = self.knob, world.poses[self.body][:3, 2]
        R0, p0, at = self._grasp
        off = world.T_world_ee[:3, 3] - at
        if float(np.linalg.norm(off)) > k.release:  # pulled off it
            self._grasp, self.torque = None, 0.0
            return np.zeros(6)
        turn = se3.rotvec_from_matrix(world.T_world_ee[:3, :3] @ R0.T)
        spin = float(turn @ axis)
        want = p0 + spin
        self.position = min(k.travel, max(0.0, want))
        self.max_position = max(self.max_position, self.position)
        w = float(world.twist[3:] @ axis)
        self.torque = -k.friction * math.tanh(w / SPIN) - STOP * (want - self.position)
        force = -k.stiffness * off - k.damping * world.twist[:3]
        moment = self.torque * axis - SHAFT * (turn - spin * axis)
        return np.concatenate([force, moment])

    def readings(self, world: World) -> dict[str, float | bool]:
        b = self.body
        return {f"{b}.position": self.position, f"{b}.held": self.held, f"{b}.grasps": float(self.grasps),
                f"{b}.max_position": self.max_position, f"{b}.torque": self.torque}


@dataclass(frozen=True)
class TurnStep(StepKind):
    """Turn ``knob`` in the hand (see the module doc).

    Attributes
    ----------
    knob : str
    force : float
        N the fingers squeeze with.
    target : float
        rad the knob is turned to: the task's ``done`` threshold of its position plus the
        overshoot (read from the file's ``overshoot``).
    overshoot : float
        rad past that threshold.
    approach, clear : float
        m back from the grip the hand comes in from, and backs away to.
    """

    key = "turn"
    grips = True

    knob: str
    force: float
    target: float
    overshoot: float = 0.0
    approach: float = 0.08
    clear: float = 0.08

    @classmethod
    def read(cls, r: Any, v: Any, path: str, scene: Scene, outcome: Outcome,
             before: tuple[Step, ...]) -> TurnStep:
        d = r.fields(v, path, {"knob", "force"}, {"overshoot", "approach", "clear"})
        name = r.name(d["knob"], f"{path}.knob")
        knobs = scene.with_facet("knob")
        if name not in knobs:
            raise r.fail(f"{path}.knob", f"{name!r} is no knob (knobs: {', '.join(knobs) or 'none'})")
        done = thresholds(outcome.done).get(f"{name}.position")
        if done is None:
            raise r.fail(f"{path}.knob", f"outcome.done sets no at_least on {name}.position: the knob has "
                                         "no position to turn it to")
        overshoot = r.angle(d.get("overshoot", 0.0), f"{path}.overshoot", lo=0.0)
        if done + overshoot > knobs[name].travel:
            raise r.fail(f"{path}.overshoot", f"turns it to {math.degrees(done + overshoot):.1f} deg, past "
                                              f"its travel of {math.degrees(knobs[name].travel):.1f} deg")
        return cls(name, r.positive(d["force"], f"{path}.force"), done + overshoot, overshoot,
                   r.positive(d.get("approach", 0.08), f"{path}.approach"),
                   r.positive(d.get("clear", 0.08), f"{path}.clear"))

    def to_yaml(self, scene: Scene) -> dict[str, Any]:
        return {"knob": self.knob, "force": _f(self.force), "overshoot": _f(self.overshoot),
                "approach": _f(self.approach), "clear": _f(self.clear)}

    def frame(self) -> str:
        return "hand"

    def mind(self, run: Run, index: int) -> StepMind:
        return TurnMind(self, facet_of(run.scene, self.knob, Knob), run.person)

    def floor_path(self, task: Task, before: tuple[Floor, ...]) -> Floor:
        """To the grip, the turn to the task's threshold, ``clear`` back."""
        scene = task.scene
        T = scene.bodies[self.knob].T_world
        grip = T[:3, 3] + facet_of(scene, self.knob, Knob).grip * T[:3, 2]
        back = grip - self.clear * _ahead(scene.start.T_world, np.zeros(3))
        return Floor((grip, back), self.target - self.overshoot)

    def legs(self, scene: Scene, poses: Mapping[str, Array], T_world_ee: Array, rng: np.random.Generator,
             mistake: bool = False) -> list[Leg]:
        """To it, in, close until it is held, turn it to the threshold plus up to the
        overshoot (slowly, about its axis), open until it is let go, back along the hand's x."""
        knob = facet_of(scene, self.knob, Knob)
        T = poses[self.knob]
        axis = T[:3, 2]
        grip = T[:3, 3] + knob.grip * axis
        R = _yawed(T_world_ee[:3, :3], rng, TURN_AWAY / 3)
        turn = self.target - self.overshoot + float(rng.uniform(0.3, 1.0)) * self.overshoot
        R_turned = se3.matrix_from_rotvec(turn * axis) @ R
        ahead = _ahead(_pose(R_turned, grip), np.zeros(3))
        return [*take_legs(R, grip, self.approach, self.force, f"{self.knob}.held", rng, mistake),
                Leg(_pose(R_turned, grip), SLOW, "open", None, (f"{self.knob}.held", False)),
                Leg(_pose(R_turned, grip - self.clear * ahead), SLOW)]


class TurnMind(StepMind):
    """A person turning a knob: to it, in, close, turn, let go, away (the module doc)."""

    def __init__(self, step: TurnStep, knob: Knob, person: Person):
        self.step, self.knob, self.person = step, knob, person
        self._from: Array | None = None  # the horizontal direction the hand comes in along
        self._in = False

    def _seen(self, sight: Sight) -> tuple[float, bool, Array, Array]:
        r, n = sight.readings, self.step.knob
        T = sight.objects[n]
        return float(r.get(f"{n}.position", 0.0)), bool(r.get(f"{n}.held", False)), \
            T[:3, 3] + self.knob.grip * T[:3, 2], T[:3, 2]

    def _turned(self, position: float) -> bool:
        return position >= self.step.target - self.step.overshoot

    def _clear_of(self, sight: Sight, axis: Array, grip: Array) -> float:
        d = sight.T_world_ee[:3, 3] - grip
        return float(np.linalg.norm(d - float(d @ axis) * axis))

    def move(self, sight: Sight) -> int:
        position, held, grip, axis = self._seen(sight)
        done = self._turned(position) and not held and self._clear_of(sight, axis, grip) >= self.step.clear
        return 1 if done else 0

    def error(self, sight: Sight) -> float:
        position, held, grip, axis = self._seen(sight)
        to_turn = max(0.0, self.step.target - position) * self.person.per_rad
        if self._turned(position) and not held:
            return max(0.0, self.step.clear - self._clear_of(sight, axis, grip))
        return to_turn + (0.0 if held else float(np.linalg.norm(grip - sight.T_world_ee[:3, 3])))

    def want(self, sight: Sight) -> Want:
        position, held, grip, axis = self._seen(sight)
        p = sight.T_world_ee[:3, 3]
        if held:
            self._from, self._in = None, False
            v = _saturate(self.person.gain * (grip - p), self.person.v_max)
            if position >= self.step.target - THERE:  # there: let go
                return Want(np.zeros(6), _weights(self.person, True), "open")
            w = axis * min(self.person.w_max, self.person.gain * (self.step.target - position))
            return Want(np.concatenate([v, w]), _weights(self.person, True), "close")
        if self._turned(position):  # let go of it there: away
            back = p - grip - float((p - grip) @ axis) * axis
            n = float(np.linalg.norm(back))
            v = 0.5 * self.person.v_max * (back / n if n > 1e-6 else -sight.T_world_ee[:3, 0])
            return Want(np.concatenate([v, np.zeros(3)]), _weights(self.person, False), None)
        goal, at = self._goal(sight, grip)
        w, off = _square(sight.T_world_ee, axis, self.person.gain)
        turning = off > math.sin(math.radians(8.0))
        v = _saturate(self.person.gain * (goal - p), self.person.v_max)
        twist = np.concatenate([v, _saturate(w, self.person.w_max) if turning else np.zeros(3)])
        return Want(twist, _weights(self.person, turning), "close" if at and not turning else None)

    def _goal(self, sight: Sight, grip: Array) -> tuple[Array, bool]:
        """Where the hand goes to take it: the point before it, then in; whether it is at the grip."""
        p = sight.T_world_ee[:3, 3]
        if self._from is None:
            self._from = _ahead(sight.T_world_ee, grip - p)
        before = grip - self.step.approach * self._from
        off = grip - p
        if self._in and float(np.linalg.norm(off - float(off @ self._from) * self._from)) > STRAY:
            self._in = False
        if not self._in and float(np.linalg.norm(before - p)) < IN_REACH:
            self._in = True
        if not self._in:
            return before, False
        e = sight.T_world_ee[:3, :3].T @ off
        return grip, all(abs(float(x)) <= tol for x, tol in zip(e, AT_GRIP, strict=True))
