"""Several tasks in one room: which one the person is going for, and when its skill
engages (pure: no I/O, no clocks; docs/goals.md).

A :class:`GoalSet` holds the members of a skill set (each skill tied to its task
object, :class:`Member`) and a teleoperation skill, the baseline's modes, which runs
while no member is engaged. Every tick the tick driver (:mod:`.driver`) asks it, before
the controller's step, whether to change the running skill (:meth:`GoalSet.decide`) and
tells it, after the step, how far the target moved (:meth:`GoalSet.observe`).

**The belief** (:class:`Belief`) is over the members whose object pose is fresh (the
candidates). A Boltzmann-rational person (Dragan and Srinivasa 2013; Javdani et al.'s
hindsight optimisation and its ``ada_assistance_policy``, which update a belief over
goals the same way) commands a motion ``d`` from ``p`` towards goal ``g`` with
probability proportional to ``exp(-beta * (Q_g - V_g))``: ``Q_g`` the cost of the motion
plus the cost-to-go from where it leads, ``V_g`` the cost-to-go from here. With the
distance to the goal's point ``x_g`` as the cost-to-go, each tick adds

    log b_g += -beta * (|d| - (|p - x_g| - |p + d - x_g|))

which is zero for motion straight at ``x_g`` and ``-2 beta |d|`` straight away; ``d``
is the target's step this tick (what the person commanded, after the speed bound), ``p``
the target before it. No motion, no evidence: zero input leaves the belief as it is;
turns carry none either (the goal points are positions). The belief is normalised over
the candidates and no candidate's falls below ``floor``, so evidence can always bring a
task back.

**Rest** is evidence too. A person going for another task does not stop at this one:
while the input is at rest, nothing is engaged and the hand is within ``rest_radius`` of
one or more candidates' goal points, every other candidate pays ``beta * rest_speed``
nats per second of rest (the tick driver's time). A rest is a stop: it counts once the
target has moved (a hand resting where the daemon found it has said nothing). In the
model's terms the cost is time as well as path: resting costs nothing at a goal already
reached, and ``rest_speed * t`` for a goal still ahead, the way a person going there at
``rest_speed`` would have come nearer. Without it a hand that stopped at a task whose
approach was also the approach to a task beyond (a mug on the way to a switch) keeps a
belief split between the two.

**Engagement.** From teleoperation, the most likely candidate engages when its belief is
at least ``threshold`` and the hand is inside its skill's start region
(:meth:`GoalSet.in_start_region`: within ``reach`` of the goal point, and the start
state's geometric constraints hold at the measured pose within tolerances, so that the
skill takes over without pulling the hand). Escape (button 2) disengages the engaged
skill and multiplies its task's belief by ``escape_factor``; automatic engagement then
waits until the target has travelled ``rearm_travel`` (the person shows where they go
next). Button 3 (choose) cycles teleoperation -> the first candidate -> the next ... ->
teleoperation, in the set's order, for a person who prefers to choose; after a choice,
as after an escape, automatic engagement waits for ``rearm_travel`` (teleoperation
chosen in a task's start region is not taken straight back). Every change of
the running skill waits for a tick whose newest input is zero or disabled: a mapping
changed under a held stick would change the direction of motion. An engaged skill stays
engaged until escape or choose: the inference never switches between skills by itself.
Nothing moves without input: the inference only chooses which mapping the person's own
input goes through.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from .. import se3
from ..skill import Skill, SkillEngine
from ..skill.constraints import NeighbourOrientation, StepLimit
from ..wire.codec import BUTTON_CHOOSE, BUTTON_ESCAPE
from .arbiter import Command

FLUSH_TICKS = 10
"""Moving ticks whose steps are summed before the belief is brought up to date."""

TELEOP = "teleop"
"""What ``status.goals.engaged`` says while no member is engaged (the teleoperation
skill's own name is in ``status.goals.teleop``; the target's ``skill`` is the running
skill's id, teleoperation's then)."""


@dataclass(frozen=True)
class BeliefModel:
    """The parameters of the belief and of automatic engagement (docs/goals.md)."""

    beta: float = 40.0
    """1/m: how sharply the person's motion points at their goal (Boltzmann rationality);
    motion at 90 degrees to a goal's direction lowers its odds by e^(beta*0.1) per 10 cm."""
    threshold: float = 0.8
    """Belief at which the most likely candidate engages (inside its start region)."""
    floor: float = 1e-3
    """No candidate's belief falls below this."""
    escape_factor: float = 1e-3
    """An escape multiplies the escaped task's belief by this (then all are normalised
    again): from the most a task can hold (three tasks: 0.998) to a third, so that the
    person's next motion decides between the others."""
    rearm_travel: float = 0.02
    """m the target travels after an escape or a choice before a task engages by itself
    again."""
    rest_radius: float = 0.10
    """m: a hand at rest this near a candidate's goal point counts as stopped there."""
    rest_speed: float = 0.10
    """m/s: the rest's evidence, as motion at this speed straight away from the goals not
    reached (``beta * rest_speed`` nats per second; 0 turns it off)."""

    def __post_init__(self) -> None:
        if not (self.beta > 0.0 and math.isfinite(self.beta)):
            raise ValueError(f"beta: expected a positive number, got {self.beta}")
        if not 0.5 < self.threshold < 1.0:
            raise ValueError(f"threshold: expected a number in (0.5, 1), got {self.threshold}")
        if not 0.0 < self.floor < 0.1:
            raise ValueError(f"floor: expected a number in (0, 0.1), got {self.floor}")
        if not 0.0 < self.escape_factor < 1.0:
            raise ValueError(f"escape_factor: expected a number in (0, 1), got {self.escape_factor}")
        if not (self.rearm_travel >= 0.0 and math.isfinite(self.rearm_travel)):
            raise ValueError(f"rearm_travel: expected a number >= 0, got {self.rearm_travel}")
        for name in ("rest_radius", "rest_speed"):
            v = getattr(self, name)
            if not (v >= 0.0 and math.isfinite(v)):
                raise ValueError(f"{name}: expected a number >= 0, got {v}")


@dataclass(frozen=True)
class Member:
    """One skill of a set and its task.

    ``point`` is the goal point in the skill's object frame (the belief's ``x_g``);
    ``reach`` (m) how far from it the start region extends; ``position_tolerance`` (m)
    and ``angle_tolerance`` (rad) how far the measured pose may be from satisfying the
    start state's active constraints and still count as inside."""

    skill: Skill
    point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    reach: float = 0.30
    position_tolerance: float = 0.01
    angle_tolerance: float = 0.15

    @property
    def name(self) -> str:
        return self.skill.name


class Belief:
    """Log-beliefs of ``n`` tasks (module doc); the candidates are passed at each use."""

    def __init__(self, n: int, model: BeliefModel):
        self.model = model
        self.log = [-math.log(n)] * n if n else []

    def update(self, p: Sequence[float], d: Sequence[float], goals: Sequence[Sequence[float] | None]) -> None:
        """The target moved by ``d`` from ``p`` (world); ``goals`` the candidates' goal
        points (None: not a candidate)."""
        dx, dy, dz = d
        self.apply(p, (p[0] + dx, p[1] + dy, p[2] + dz), math.sqrt(dx * dx + dy * dy + dz * dz), goals)

    def apply(self, p0: Sequence[float], p1: Sequence[float], length: float,
              goals: Sequence[Sequence[float] | None]) -> None:
        """The target went from ``p0`` to ``p1`` along a path of ``length`` m, the goal
        points staying where they are: the sum of the path's ticks' updates, since the
        cost-to-go differences telescope (``sum(c(p_k) - c(p_k+1)) = c(p0) - c(p1)``)."""
        if not length > 0.0:
            return
        px, py, pz = p0
        qx, qy, qz = p1
        beta, log = self.model.beta, self.log
        for i, g in enumerate(goals):
            if g is None:
                continue
            gx, gy, gz = g
            before = math.sqrt((px - gx) ** 2 + (py - gy) ** 2 + (pz - gz) ** 2)
            after = math.sqrt((qx - gx) ** 2 + (qy - gy) ** 2 + (qz - gz) ** 2)
            log[i] -= beta * (length - (before - after))
        self._normalise([g is not None for g in goals])

    def charge(self, paying: Sequence[bool], nats: float, candidates: Sequence[bool]) -> None:
        """Lower the log-belief of every task in ``paying`` by ``nats`` (a rest away from
        their goals), renormalised. Those already at the floor stay there and the others'
        shares do not change: nothing to do (a long rest, every tick)."""
        at_floor = math.log(self.model.floor) + 1e-12
        if all(self.log[i] <= at_floor for i, pays in enumerate(paying) if pays):
            return
        for i, pays in enumerate(paying):
            if pays:
                self.log[i] -= nats
        self._normalise(candidates)

    def lower(self, i: int, factor: float, candidates: Sequence[bool]) -> None:
        """Multiply task ``i``'s belief by ``factor`` (an escape), renormalised."""
        self.log[i] += math.log(factor)
        self._normalise(candidates)

    def probabilities(self, candidates: Sequence[bool]) -> list[float]:
        """The belief over the candidates (0 for the others)."""
        idx = [i for i, c in enumerate(candidates) if c]
        if not idx:
            return [0.0] * len(self.log)
        top = max(self.log[i] for i in idx)
        w = [math.exp(self.log[i] - top) if c else 0.0 for i, c in enumerate(candidates)]
        total = sum(w)
        return [x / total for x in w]

    def _normalise(self, candidates: Sequence[bool]) -> None:
        """Log-probabilities over the candidates, none below the floor: those below it are
        raised to it and the others share the rest in proportion (the non-candidates keep
        their last value: an object seen again comes back with the belief it left with)."""
        idx = [i for i, c in enumerate(candidates) if c]
        if not idx:
            return
        log, floor = self.log, self.model.floor
        top = max(log[i] for i in idx)
        p = {i: math.exp(log[i] - top) for i in idx}
        low: set[int] = set()
        while True:
            free = [i for i in idx if i not in low]
            total = sum(p[i] for i in free)
            share = 1.0 - floor * len(low)
            new = {i for i in free if p[i] / total * share < floor}
            if not new or len(new) == len(free):
                break
            low |= new
        for i in idx:
            log[i] = math.log(floor) if i in low else math.log(p[i] / total * share)


@dataclass
class GoalCounters:
    engagements: int = 0  # automatic, by the belief
    choices: int = 0  # by the choose button (to a member or back to teleoperation)
    escapes: int = 0  # disengagements by escape
    deferred: int = 0  # changes asked for while the input was held (done at the next rest)
    by_member: dict[str, int] = field(default_factory=dict)  # engagements of each member


class GoalSet:
    """The members, the teleoperation skill, the belief and the engagement rule (module
    doc).

    Parameters
    ----------
    members : sequence of Member
        At least one; their skills' names differ.
    teleop : Skill
        What runs while no member is engaged (its object: the world).
    model : BeliefModel
    engines : sequence of SkillEngine, optional
        The members' engines, built elsewhere (KD-trees take time); default built here.
    """

    def __init__(self, members: Sequence[Member], teleop: Skill, model: BeliefModel | None = None,
                 engines: Sequence[SkillEngine] | None = None):
        if not members:
            raise ValueError("a skill set needs at least one member")
        names = [m.name for m in members]
        if len(set(names)) != len(names) or teleop.name in names:
            raise ValueError(f"the set's skill names must differ (and from teleoperation's): {names}")
        self.members = tuple(members)
        self.teleop = teleop
        self.model = model if model is not None else BeliefModel()
        self.engines = list(engines) if engines is not None else [SkillEngine(m.skill) for m in members]
        self.teleop_engine = SkillEngine(teleop)
        self.belief = Belief(len(members), self.model)
        self.engaged: int | None = None
        # every body a member names (the driver keeps their poses)
        self.objects = frozenset(o for m in members for o in m.skill.objects())
        self.counters = GoalCounters()
        self.candidates = [False] * len(members)
        self._goals: list[tuple[float, float, float] | None] = [None] * len(members)
        self._pending: tuple[str, int | None] | None = None  # ("escape"|"choose", member)
        self._travel = math.inf  # the target's travel since the last escape
        self._F_obj: list[se3.Flat | None] = [None] * len(members)  # the objects' poses (world)
        # the target's steps not yet in the belief: where they began and ended, their length
        self._p0: tuple[float, float, float] | None = None
        self._p1: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._path = 0.0
        self._steps = 0
        self._rest_at: float | None = None  # the time of the last tick at rest that was weighed
        self._moved = False  # whether the target has moved at all (a rest is a stop after motion)

    # --- what the driver asks ------------------------------------------------------------

    @property
    def running(self) -> tuple[Skill, SkillEngine]:
        """The skill that runs now and its engine."""
        if self.engaged is None:
            return self.teleop, self.teleop_engine
        return self.members[self.engaged].skill, self.engines[self.engaged]

    def see(self, fresh: Mapping[str, se3.Flat]) -> None:
        """The fresh task objects' poses (world) this tick: the candidates and their goal
        points (worked out again only for a new pose: the same tuple is the same pose)."""
        for i, m in enumerate(self.members):
            F = fresh.get(m.skill.object)
            if F is self._F_obj[i]:
                continue
            self._flush()  # (the path so far belongs to the goal points it was walked by)
            self.candidates[i] = F is not None
            self._F_obj[i] = F
            if F is None:
                self._goals[i] = None
            else:
                x, y, z = m.point
                self._goals[i] = (F[0] * x + F[1] * y + F[2] * z + F[9],
                                  F[3] * x + F[4] * y + F[5] * z + F[10],
                                  F[6] * x + F[7] * y + F[8] * z + F[11])

    def decide(self, cmd: Command, F_hand: se3.Flat | None, at_rest: bool,
               now: float) -> tuple[Command, bool]:
        """Before the controller's step: the command it should follow (the set's own
        buttons taken out of it) and whether the running skill changed (:attr:`running`).

        ``F_hand`` is the measured hand pose (world), None while there is none;
        ``at_rest`` whether every input device's newest message is at rest
        (:meth:`.arbiter.InputArbiter.at_rest`): only then may the running skill change;
        ``now`` the tick's time (s, any origin): how long a rest has lasted."""
        pressed = cmd.pressed
        at_rest = at_rest and not any(cmd.u)
        if BUTTON_CHOOSE in pressed or (BUTTON_ESCAPE in pressed and self.engaged is not None):
            self._press(pressed)
            self.counters.deferred += not at_rest
            pressed = pressed - {BUTTON_CHOOSE, BUTTON_ESCAPE} if self.engaged is not None \
                else pressed - {BUTTON_CHOOSE}
            cmd = cmd._replace(pressed=pressed)
        if at_rest and self._pending is None and self.engaged is None and F_hand is not None \
                and self._travel >= self.model.rearm_travel:
            self._flush()
            self._weigh_rest(F_hand, now)
            return cmd, self._maybe_engage(F_hand)
        self._rest_at = None
        if not at_rest:
            return cmd, False
        self._flush()
        if self._pending is not None:
            return cmd, self._apply_pending()
        return cmd, False

    def observe(self, before: Sequence[float] | None, after: Sequence[float] | None) -> None:
        """After the controller's step: the target's position before and after it (world;
        None when there was none, or when the new one is a seed rather than a step).

        The steps are summed (their path length, where they began and ended) and the
        belief is brought up to date every :data:`FLUSH_TICKS` moving ticks, before a
        decision and before a status: the same belief, at a tenth of the work."""
        if before is None or after is None:
            return
        dx, dy, dz = after[0] - before[0], after[1] - before[1], after[2] - before[2]
        step = math.sqrt(dx * dx + dy * dy + dz * dz)
        if not step > 0.0:
            return
        self._moved, self._rest_at = True, None  # (a step ends a rest)
        if self._p0 is None:
            self._p0 = (before[0], before[1], before[2])
        self._p1 = (after[0], after[1], after[2])
        self._path += step
        if self._travel < self.model.rearm_travel:
            self._travel += step
        self._steps += 1
        if self._steps >= FLUSH_TICKS:
            self._flush()

    def _flush(self) -> None:
        """The summed steps into the belief."""
        if self._p0 is not None:
            self.belief.apply(self._p0, self._p1, self._path, self._goals)
            self._p0, self._path, self._steps = None, 0.0, 0

    # --- the rule ------------------------------------------------------------------------

    def _press(self, pressed: frozenset[int]) -> None:
        """An escape (while engaged) or a choice: done at the next tick at rest; the
        newest press wins."""
        if BUTTON_ESCAPE in pressed and self.engaged is not None:
            self._pending = ("escape", self.engaged)
        if BUTTON_CHOOSE in pressed:
            self._pending = ("choose", self._next_choice())

    def _next_choice(self) -> int | None:
        """The member after the one engaged (or chosen and waiting) in the set's order,
        skipping those without a fresh object; None (teleoperation) after the last."""
        at = self.engaged
        if self._pending is not None and self._pending[0] == "choose":
            at = self._pending[1]
        start = -1 if at is None else at
        for i in range(start + 1, len(self.members)):
            if self.candidates[i]:
                return i
        return None

    def _apply_pending(self) -> bool:
        kind, i = self._pending  # type: ignore[misc]
        self._pending = None
        if kind == "escape":
            if self.engaged != i:
                return False
            assert i is not None
            self.belief.lower(i, self.model.escape_factor, self.candidates)
            self.counters.escapes += 1
            self._travel = 0.0
            self.engaged = None
            return True
        self.counters.choices += 1
        self._travel = 0.0  # (teleoperation chosen: not taken back before the person moves)
        if i is not None and not self.candidates[i]:
            return False  # its object went stale meanwhile
        changed = i != self.engaged
        self.engaged = i
        return changed

    def _weigh_rest(self, F_hand: se3.Flat, now: float) -> None:
        """A tick at rest, unengaged and armed: the rest since the last such tick is
        evidence against the candidates whose goal points are farther than
        ``rest_radius`` while one is nearer, once the target has moved (module doc)."""
        last, self._rest_at = self._rest_at, now
        nats_per_s = self.model.beta * self.model.rest_speed
        if last is None or not now > last or not nats_per_s > 0.0 or not self._moved:
            return
        h, r2 = F_hand[9:12], self.model.rest_radius ** 2
        near = [g is not None and (h[0] - g[0]) ** 2 + (h[1] - g[1]) ** 2 + (h[2] - g[2]) ** 2 <= r2
                for g in self._goals]
        if any(near):
            paying = [g is not None and not n for g, n in zip(self._goals, near, strict=True)]
            self.belief.charge(paying, nats_per_s * (now - last), self.candidates)

    def _maybe_engage(self, F_hand: se3.Flat) -> bool:
        p = self.belief.probabilities(self.candidates)
        best = max(range(len(p)), key=p.__getitem__)
        if not (self.candidates[best] and p[best] >= self.model.threshold):
            return False
        if not self.in_start_region(best, F_hand):
            return False
        self.engaged = best
        self.counters.engagements += 1
        name = self.members[best].name
        self.counters.by_member[name] = self.counters.by_member.get(name, 0) + 1
        return True

    def in_start_region(self, i: int, F_hand: se3.Flat) -> bool:
        """Whether the measured hand pose (world) is inside member ``i``'s start region:
        within ``reach`` of its goal point, and its start state's geometric active
        constraints (a tilt cone, a band, a box) hold within the tolerances. A
        neighbour orientation is not judged: it turns the hand towards the
        demonstrations only as far as the person pushes, and a step limit only bounds
        steps."""
        m, g, F_obj = self.members[i], self._goals[i], self._F_obj[i]
        if g is None or F_obj is None:
            return False
        x, y, z = F_hand[9], F_hand[10], F_hand[11]
        if (x - g[0]) ** 2 + (y - g[1]) ** 2 + (z - g[2]) ** 2 > m.reach * m.reach:
            return False
        engine = self.engines[i]
        F = se3.compose_flat(se3.invert_flat(F_obj), F_hand)
        start = m.skill.states[m.skill.state_index(m.skill.start)]
        for c in start.active_constraints:
            if isinstance(c, StepLimit | NeighbourOrientation):
                continue  # (they bound a step, or steer as far as the person pushes)
            P = engine.project(F, c)
            if P is F:
                continue
            if math.dist(P[9:], F[9:]) > m.position_tolerance or \
                    _angle(P, F) > m.angle_tolerance:
                return False
        return True

    # --- a member replaced (a swap) --------------------------------------------------------

    def index(self, name: str) -> int:
        """The member named ``name`` (a skill's name).

        Raises
        ------
        KeyError
            Naming the members.
        """
        for i, m in enumerate(self.members):
            if m.name == name:
                return i
        raise KeyError(f"no member {name!r} in the set (members: {', '.join(m.name for m in self.members)})")

    def replace(self, name: str, skill: Skill, engine: SkillEngine | None = None) -> bool:
        """Put ``skill`` in the place of member ``name`` (its point, reach and tolerances
        kept; its belief kept). Returns whether that member is the engaged one (the
        caller then swaps the running skill as a single skill's swap does)."""
        i = self.index(name)
        others = [m.name for k, m in enumerate(self.members) if k != i]
        if skill.name in others or skill.name == self.teleop.name:
            raise ValueError(f"{skill.name!r} is the name of another member of the set")
        old = self.members[i]
        self.members = (*self.members[:i], replace(old, skill=skill), *self.members[i + 1:])
        self.engines[i] = engine if engine is not None else SkillEngine(skill)
        self.objects = frozenset(o for m in self.members for o in m.skill.objects())
        return self.engaged == i

    # --- what the status says ------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        """``status.goals`` (docs/wire-contract.md)."""
        self._flush()
        p = self.belief.probabilities(self.candidates)
        c = self.counters
        pending = None if self._pending is None else {
            "kind": self._pending[0],
            "member": TELEOP if self._pending[1] is None else self.members[self._pending[1]].name}
        return {
            "engaged": TELEOP if self.engaged is None else self.members[self.engaged].name,
            "teleop": self.teleop.name,
            "belief": {m.name: round(p[i], 4) for i, m in enumerate(self.members) if self.candidates[i]},
            "objects": {m.name: m.skill.object for m in self.members},
            "threshold": self.model.threshold,
            "pending": pending,
            "counters": {"engagements": c.engagements, "choices": c.choices, "escapes": c.escapes,
                         "deferred": c.deferred, "by_member": dict(c.by_member)},
        }


def _angle(A: se3.Flat, B: se3.Flat) -> float:
    """The angle (rad) between two flat poses' rotations."""
    tr = sum(A[k] * B[k] for k in range(9))  # trace(R_A^T R_B)
    return math.acos(max(-1.0, min(1.0, (tr - 1.0) / 2.0)))
