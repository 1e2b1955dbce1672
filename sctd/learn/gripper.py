"""The hand's fingers in learned skills: gripper events are phase boundaries.

Demonstrations with the gripper's columns (:data:`sctd.learn.demos.GRIPPER_COLUMNS`)
say where the fingers started to hold something (a **close**: ``grasped`` 0 -> 1) and
where they let go (an **open**: 1 -> 0). :func:`plan_gripper` finds these events, the
same sequence in every demonstration, and where the hand was at each (object frame).
:func:`with_gripper` splits the learned skill's states at them, whatever method learned
them: each state is copied into every phase (the stretch between two events) whose
displacements it labels, with the transitions between its copies, and each event
becomes a state of its own that commands the gripper at its entry::

    ... phase e's states --(hand where the demonstrations closed)--> grasp state
        (gripper: {action: close, force: F}; phase e's last mapping)
        --(gripper grasped: true)--> phase e+1's first state
        --(timeout grasp_timeout, the grasp failed)--> phase e's last state

An open is the same with ``{action: open}`` and ``grasped: false``. Where the hand's
position does not tell the event from the start of its phase (the demonstrations began
the phase within reach of where it ended, e.g. a cup carried in the cup's own frame
sits still in it), the way into the event's state is the reading itself: the person
closes or opens with the grasp button, and the state follows, repeating the command.
No state but an event's commands the gripper, and an event's state is entered only by
its event's transition.

Pure: no I/O.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..skill import Distance, Gripper, GripperAction, InputMapping, Skill, State, Timeout, Transition
from .demos import Demo
from .params import Interval, hyperparameter

Array = NDArray[np.float64]


class GripperError(ValueError):
    """Demonstrations whose gripper events cannot be learned from (mixed columns, other
    sequences of events), naming the demonstration."""


@dataclass(frozen=True)
class GripperOptions:
    """How gripper events become states (used only where the demonstrations have them).

    Parameters
    ----------
    grasp_force : float
        N: the force bound of a learned close (the task's grasp force where the caller
        knows it).
    grasp_timeout : float
        s an event's state waits for the fingers' reading (holding after a close, empty
        after an open) before it returns to the state before it.
    gripper_radius : float
        m: the smallest radius of the place an event's distance transition fires in
        (otherwise twice the demonstrations' spread there); the hand must start its phase
        further than twice this from it for the position to tell the event. 8 mm: the
        fingers take a cup or a knob with its axis within 1-1.5 cm of their middle, so a
        close that fires further out closes beside it (a learned tap closed 2 cm short of
        its handle and held in 16 of 20 lockstep trials with 2 cm, in 20 of 20 with 8 mm).
    """

    grasp_force: float = hyperparameter(20.0, "N: the force bound of a learned close (default "
                                        "%(default)s)", valid=Interval(0, 1000, open="low"))
    grasp_timeout: float = hyperparameter(3.0, "s a learned grasp (or release) waits for the fingers' "
                                          "reading before it goes back (default %(default)s)",
                                          valid=Interval(0.1, 60))
    gripper_radius: float = hyperparameter(0.008, "m: the smallest radius of a gripper event's place "
                                           "(default %(default)s)", valid=Interval(0.002, 0.2))


@dataclass(frozen=True)
class GripperEvent:
    """The ``index``-th event: ``action`` (``close`` or ``open``), the median ee
    position (3,) at it (object frame), the RMS ``spread`` of the demonstrations' positions
    about it, the ``radius`` of its distance transition, and whether the position tells
    it (``by_position``; else the reading does)."""

    index: int
    action: str
    point: Array
    spread: float
    radius: float
    by_position: bool
    # The same in each other body's frame the demonstrations carry (body -> (point,
    # radius, by_position)): the way in from a state in that body's frame.
    by_body: dict[str, tuple[Array, float, bool]] = field(default_factory=dict)

    def place(self, body: str | None) -> tuple[Array, float, bool]:
        """(point, radius, by_position) in ``body``'s frame (None: the task object's)."""
        return (self.point, self.radius, self.by_position) if body is None else self.by_body[body]


@dataclass(frozen=True)
class GripperPlan:
    """The events, in order, and per demonstration the phase of each raw displacement
    (row i -> i + 1; phase e lies between events e - 1 and e)."""

    events: tuple[GripperEvent, ...]
    phases: dict[str, list[int]]


def event_rows(demo: Demo) -> list[tuple[int, str]]:
    """(row, action) where ``grasped`` changes: the first row of the new reading."""
    if demo.grasped is None:
        return []
    g = np.asarray(demo.grasped, dtype=bool)
    rows = np.flatnonzero(g[1:] != g[:-1]) + 1
    return [(int(r), "close" if g[r] else "open") for r in rows]


def plan_gripper(demos: list[Demo], options: GripperOptions | None = None) -> GripperPlan | None:
    """The gripper events of ``demos``, or None when none has the gripper's columns or
    none of them closes or opens (then nothing about the skill changes).

    Raises
    ------
    GripperError
        Some demonstrations have the columns and some do not, or their sequences of
        events differ (the message names the demonstration).
    """
    options = GripperOptions() if options is None else options
    have = [d for d in demos if d.grasped is not None]
    if not have:
        return None
    lacking = next((d for d in demos if d.grasped is None), None)
    if lacking is not None:
        raise GripperError(f"{lacking.name}: no gripper columns, but {have[0].name} has them "
                           "(learn from demonstrations that all have them or none)")
    rows = {d.name: event_rows(d) for d in demos}
    first = demos[0]
    sequence = [a for _, a in rows[first.name]]
    for d in demos[1:]:
        other = [a for _, a in rows[d.name]]
        if other != sequence:
            raise GripperError(f"{d.name}: gripper events {other or 'none'}, but {first.name} has "
                               f"{sequence or 'none'} (every demonstration must close and open alike)")
    if not sequence:
        return None
    events = tuple(_event(demos, rows, e, a, options) for e, a in enumerate(sequence))
    phases = {d.name: np.searchsorted([r for r, _ in rows[d.name]], np.arange(len(d) - 1),
                                      side="right").tolist() for d in demos}
    return GripperPlan(events, phases)


def _event(demos: list[Demo], rows: dict[str, list[tuple[int, str]]], e: int, action: str,
           options: GripperOptions) -> GripperEvent:
    """The ``e``-th event over all demonstrations (in the task object's frame, and in
    each other body's every demonstration carries)."""
    bodies = [b for b in demos[0].bodies if all(b in d.bodies for d in demos)]
    point, spread, radius, by_position = _place(demos, rows, e, None, options)
    by_body = {}
    for b in bodies:
        p, _, r, pos = _place(demos, rows, e, b, options)
        by_body[b] = (p, r, pos)
    return GripperEvent(e, action, point, spread, radius, by_position, by_body)


def _place(demos: list[Demo], rows: dict[str, list[tuple[int, str]]], e: int, body: str | None,
           options: GripperOptions) -> tuple[Array, float, float, bool]:
    """The median hand position at event ``e`` in ``body``'s frame (None: the task
    object's), the demonstrations' RMS spread about it, the distance transition's radius
    and whether the position tells the event from the start of its phase."""
    poses = [d.poses if body is None else d.poses_in(body) for d in demos]
    at = np.array([P[rows[d.name][e][0], :3] for P, d in zip(poses, demos, strict=True)])
    point = np.median(at, axis=0)
    spread = float(np.sqrt(np.mean(np.sum((at - point) ** 2, axis=1))))
    radius = max(options.gripper_radius, 2.0 * spread)
    starts = np.array([P[0 if e == 0 else rows[d.name][e - 1][0], :3]
                       for P, d in zip(poses, demos, strict=True)])
    far = np.linalg.norm(starts - point, axis=1) > radius + 2.0 * options.gripper_radius
    return point, spread, radius, bool(np.all(far))


def _most_common(values: list[int], fallback: int) -> int:
    """The most common value (the smallest of a tie), or ``fallback`` for none."""
    if not values:
        return fallback
    counts = Counter(values)
    best = max(counts.values())
    return min(v for v, c in counts.items() if c == best)


@dataclass(frozen=True)
class _Phases:
    """Per phase: the learned states it uses (sorted), the one it starts in and the one it
    ends in (indices into the learned skill's states)."""

    used: list[list[int]]
    entry: list[int]
    exit: list[int]


def _phases(skill: Skill, labels: dict[str, list[int]], plan: GripperPlan) -> _Phases:
    n = len(plan.events) + 1
    used: list[set[int]] = [set() for _ in range(n)]
    firsts: list[list[int]] = [[] for _ in range(n)]
    lasts: list[list[int]] = [[] for _ in range(n)]
    for name, phase in plan.phases.items():
        lab = labels[name]
        for p in range(n):
            idx = [i for i, q in enumerate(phase) if q == p]
            used[p].update(lab[i] for i in idx)
            if idx:
                firsts[p].append(lab[idx[0]])
                lasts[p].append(lab[idx[-1]])
    entry: list[int] = [skill.state_index(skill.start)]
    exit_: list[int] = []
    for p in range(n):
        if p > 0:
            entry.append(_most_common(firsts[p], exit_[-1]))
        exit_.append(_most_common(lasts[p], entry[p]))
        used[p] |= {entry[p], exit_[p]}
    return _Phases([sorted(u) for u in used], entry, exit_)


def with_gripper(skill: Skill, labels: dict[str, list[int]], plan: GripperPlan,
                 options: GripperOptions | None = None, frame: str | None = None,
                 moves: dict[int, tuple[InputMapping, ...]] | None = None) -> Skill:
    """``skill`` (learned, one state per label of ``labels``) split at ``plan``'s events,
    each event a state commanding the gripper (the module's docstring). ``frame`` is the
    body whose frame the plan's places are in (None: the skill's object); a way into an
    event from a state in another body's frame uses the place in that body's. ``moves``
    (phase -> input mappings): the phase's states, and the event state after it, move
    by these instead, with no active constraints (a turn in place, :mod:`.vfturns`).

    The states are named ``s0``, ``s1``, ... in order: phase 0's, the first event's, phase
    1's, and so on.
    """
    options = GripperOptions() if options is None else options
    ph = _phases(skill, labels, plan)
    states: list[State] = []
    name_of: dict[tuple[int, int], str] = {}  # (phase, learned state) -> new name
    event_state: list[str] = []
    for p, used in enumerate(ph.used):
        move: dict[str, Any] = {} if p not in (moves or {}) else \
            {"input_mappings": moves[p], "active_constraints": ()}  # type: ignore[index]
        for k in used:
            name_of[p, k] = f"s{len(states)}"
            states.append(dataclasses.replace(skill.states[k], name=name_of[p, k], **move))
        if p < len(plan.events):
            ev = plan.events[p]
            action = (GripperAction(action="close", force=float(options.grasp_force)) if ev.action == "close"
                      else GripperAction(action="open"))
            event_state.append(f"s{len(states)}")
            states.append(dataclasses.replace(skill.states[ph.exit[p]], name=event_state[-1], gripper=action,
                                              **move))
    index = {s.name: k for k, s in enumerate(skill.states)}
    transitions: list[Transition] = []
    for p, used in enumerate(ph.used):  # the learned transitions, within each phase
        transitions += [dataclasses.replace(t, source=name_of[p, index[t.source]],
                                            target=name_of[p, index[t.target]])
                        for t in skill.transitions if index[t.source] in used and index[t.target] in used]
    frame = skill.object if frame is None else frame
    own = {s.name: None if (s.object or skill.object) == frame else s.object or skill.object
           for s in states}  # each state's body, None where it is the plan's frame
    for ev, name in zip(plan.events, event_state, strict=True):
        transitions += _event_transitions(ev, name, [(name_of[ev.index, k], own[name_of[ev.index, k]])
                                                     for k in ph.used[ev.index]],
                                          name_of[ev.index, ph.exit[ev.index]],
                                          name_of[ev.index + 1, ph.entry[ev.index + 1]], options)
    last = len(plan.events)
    end = index[skill.end]
    start = name_of[0, ph.entry[0]]
    states, transitions = _reachable(states, transitions, start)
    return _renamed(dataclasses.replace(
        skill, states=tuple(states), transitions=tuple(transitions), start=start,
        end=name_of[last, end] if (last, end) in name_of else name_of[last, ph.exit[last]],
        min_dwell=max(skill.min_dwell, 0.1), id=""))


def _reachable(states: list[State], transitions: list[Transition], start: str
               ) -> tuple[list[State], list[Transition]]:
    """The states a transition reaches from ``start`` (with the transitions between them):
    a learned state the demonstrations used in a phase but never entered from the phase's
    entry there (a copy no learned transition leads to) is left out, with its transitions."""
    seen, todo = {start}, [start]
    while todo:
        here = todo.pop()
        for t in transitions:
            if t.source == here and t.target not in seen:
                seen.add(t.target)
                todo.append(t.target)
    return ([s for s in states if s.name in seen],
            [t for t in transitions if t.source in seen and t.target in seen])


def _renamed(skill: Skill) -> Skill:
    """``skill`` with its states named ``s0``, ``s1``, ... in their order (GripperError when
    its end is not among them: no way through the events reaches it)."""
    new = {s.name: f"s{k}" for k, s in enumerate(skill.states)}
    if skill.end not in new:
        raise GripperError("no learned transition leads from the start through the gripper events to the "
                           "end: the demonstrations' phases share no state the learner could join them by")
    return dataclasses.replace(
        skill, states=tuple(dataclasses.replace(s, name=new[s.name]) for s in skill.states),
        transitions=tuple(dataclasses.replace(t, source=new[t.source], target=new[t.target])
                          for t in skill.transitions),
        start=new[skill.start], end=new[skill.end])


def _event_transitions(ev: GripperEvent, name: str, before: list[tuple[str, str | None]], exit_: str,
                       after: str, options: GripperOptions) -> list[Transition]:
    """Into the event's state ``name`` from the phase's states ``before`` (each with its
    own object: the place is in its frame); out of it to ``after`` once the fingers read
    as they should, back to ``exit_`` when they do not within the timeout."""
    holds = ev.action == "close"
    into: list[Transition] = []
    for s, body in before:
        at, radius, by_position = ev.place(body)
        if by_position:
            point = np.array([round(float(x), 6) for x in at])
            into.append(Distance(source=s, target=name, frame="ee", point=point, threshold=round(radius, 6),
                                 direction="below", margin=0.0))
        else:
            into.append(Gripper(source=s, target=name, grasped=holds))
    return [*into, Gripper(source=name, target=after, grasped=holds),
            Timeout(source=name, target=exit_, after=float(options.grasp_timeout))]


def gripper_lines(plan: GripperPlan, skill: Skill) -> list[str]:
    """One line per event for the skill's header: where, how it is entered, its state."""
    out = []
    by_action = {s.name: s for s in skill.states if s.gripper is not None}
    names = list(by_action)
    for ev, name in zip(plan.events, names, strict=False):
        how = (f"the hand within {ev.radius * 100:.1f} cm of {[round(float(x), 3) for x in ev.point]}"
               if ev.by_position else
               f"the fingers {'holding' if ev.action == 'close' else 'empty'} (the grasp button; the "
               "position does not tell this place)")
        out.append(f"{name}: gripper {ev.action} where the demonstrations did ({how}; "
                   f"{ev.spread * 100:.1f} cm RMS apart)")
    return out
