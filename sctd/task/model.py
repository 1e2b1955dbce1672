"""What a task is, as its file says it (pure data; :mod:`.reader` builds it from YAML).

A task knows nothing of any skill. It holds:

- the **scene**: where the hand starts and how much that varies between trials; the
  bodies standing in the world (each a frame, optionally a container whose opening is
  at its origin); what the hand holds (mass, centre of mass, named frames such as a
  bottle's opening, contents that flow out when it is tilted); joints moving a handle
  the hand grasps (prismatic: a drawer; revolute: a hinged door); a body's solid
  surface the hand touches and the push button on it (a light switch); a person's head
  the hand and what it holds must not press into (its mouth a body on its surface);
- the **task object**: the body whose frame demonstrations and skills are expressed in;
- the **outcome**: predicates on the scene's readings (:class:`Reading`) saying when
  the task is done, whether it then succeeded, what ends it early as a failure, what
  counts as progress, when the completion clock starts, and the time limit;
- the **intent**: what a person doing the task wants, as ordered sub-goals (:class:`Step`)
  in the task object's frame, each of a registered kind (:mod:`sctd.task.kinds`): reach
  a region, tilt, bring upright, move a joint, press a button, take an item, ...;
- **teach**: how a person's demonstrations of it vary (:class:`Teach`).

Every pose is in the world frame, the arm's base (x forward, z up), in metres and
radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:  # (the kinds' classes type their scene with this module's)
    from .kinds import Facet, Section, StepKind
    from .kinds.contents import Container, Contents
    from .kinds.joint import Joint
    from .kinds.surface import Button, Surface

Array = NDArray[np.float64]

VERSION = 1
"""The ``sctd_task`` version this code reads."""


# -- the scene ------------------------------------------------------------------------
@dataclass(frozen=True)
class Vary:
    """How much a pose varies between trials (uniform, each way).

    Attributes
    ----------
    position : ndarray, shape (3,)
        m along each world axis.
    yaw : float
        rad about the world's vertical.
    """

    position: Array = field(default_factory=lambda: np.zeros(3))
    yaw: float = 0.0


@dataclass(frozen=True)
class Body:
    """Something standing in the world.

    Attributes
    ----------
    name : str
        Its frame's name (published on ``sctd/<robot>/objects/<name>``).
    T_world : ndarray, shape (4, 4)
        Its default pose.
    vary : Vary
        How far a trial's pose is from the default.
    facets : dict of str to Facet
        Its elements of the registered kinds (:mod:`sctd.task.kinds`), by key: a
        ``container`` things are poured into, a ``surface`` the hand touches and a
        ``button`` in it, a ``support`` things rest on, an ``item`` the hand picks up.
    """

    name: str
    T_world: Array
    vary: Vary = field(default_factory=Vary)
    facets: dict[str, Facet] = field(default_factory=dict)

    @property
    def container(self) -> Container | None:
        """Its ``container`` facet (its opening the body's origin), if it has one."""
        return self.facets.get("container")  # type: ignore[return-value]

    @property
    def surface(self) -> Surface | None:
        """Its ``surface`` facet (a wall: the plane through its origin normal to its x
        axis), if it has one."""
        return self.facets.get("surface")  # type: ignore[return-value]

    @property
    def button(self) -> Button | None:
        """Its ``button`` facet (a push button in its surface), if it has one."""
        return self.facets.get("button")  # type: ignore[return-value]


@dataclass(frozen=True)
class Held:
    """The object the hand holds from the start.

    Attributes
    ----------
    name : str
    mass : float
        kg, empty.
    com : ndarray, shape (3,)
        Centre of mass in the hand's frame, m (the contents' too).
    frames : dict of str to ndarray (4, 4)
        Named frames fixed in the hand's frame (``T_ee_frame``), published as objects.
    facets : dict of str to Facet
        Its elements of the registered kinds (:mod:`sctd.task.kinds`) whose holder is the
        held object, by key: its ``contents``.
    """

    name: str
    mass: float
    com: Array
    frames: dict[str, Array]
    facets: dict[str, Facet] = field(default_factory=dict)

    @property
    def contents(self) -> Contents | None:
        """Its ``contents`` facet (what flows out of it when tilted), if it has one."""
        return self.facets.get("contents")  # type: ignore[return-value]


@dataclass(frozen=True)
class Start:
    """The hand's start: ``T_world`` and how much it varies between trials."""

    T_world: Array
    vary: Vary = field(default_factory=Vary)


@dataclass(frozen=True)
class Scene:
    """Everything in the world, and the hand's start.

    ``sections`` holds the scene's sections of registered kinds
    (:class:`~sctd.task.kinds.Section`: ``scene.<key>.<name>`` in a file: the ``joints``,
    a person's ``heads``, the ``zones``), by their key and then their entries' names, in
    the kinds' order; a section the file does not give is not there."""

    start: Start
    bodies: dict[str, Body]
    held: Held | None = None
    sections: dict[str, dict[str, Section]] = field(default_factory=dict)

    @property
    def joints(self) -> dict[str, Joint]:
        """The entries of the ``joints`` section (:class:`~sctd.task.kinds.joint.Joint`)."""
        return self.section("joints")

    @property
    def heads(self) -> dict[str, Any]:
        """The entries of the ``heads`` section (a person's heads: :class:`~sctd.task.kinds.head.Head`)."""
        return self.section("heads")

    @property
    def zones(self) -> dict[str, Any]:
        """The entries of the ``zones`` section (:class:`~sctd.task.kinds.zone.Zone`)."""
        return self.section("zones")

    def section(self, key: str) -> dict[str, Any]:
        """The entries of section ``key``, by name (none when the file gives none)."""
        return self.sections.get(key, {})

    def frames(self) -> list[str]:
        """The names of every published frame: the bodies', then the held object's, then
        the frames of the bodies' facets (an item's named frames)."""
        extra = [n for b in self.bodies.values() for f in b.facets.values() for n in f.frame_names()]
        return [*self.bodies, *(self.held.frames if self.held else ()), *extra]

    def with_facet(self, key: str) -> dict[str, Any]:
        """The bodies' facets of kind ``key``, by body name."""
        return {n: b.facets[key] for n, b in self.bodies.items() if key in b.facets}


# -- predicates -----------------------------------------------------------------------


@dataclass(frozen=True)
class Reading:
    """``<element>.<quantity>``: what the scene's elements of each kind report (their
    kind's class says, :mod:`sctd.task.kinds`)."""

    element: str
    quantity: str

    def __str__(self) -> str:
        return f"{self.element}.{self.quantity}"


@dataclass(frozen=True)
class Compare:
    """A reading against bounds: ``at_least <= x <= at_most``, ``above < x < below``,
    or, for a flag, ``x == is_``."""

    reading: Reading
    at_least: float | None = None
    at_most: float | None = None
    above: float | None = None
    below: float | None = None
    is_: bool | None = None


@dataclass(frozen=True)
class Near:
    """The frame ``frame`` (a published frame, or ``hand``) within ``within`` m of the
    origin of ``to`` (a body)."""

    frame: str
    to: str
    within: float


@dataclass(frozen=True)
class AllOf:
    terms: tuple[Predicate, ...]


@dataclass(frozen=True)
class AnyOf:
    terms: tuple[Predicate, ...]


@dataclass(frozen=True)
class Not:
    term: Predicate


Predicate = Compare | Near | AllOf | AnyOf | Not | bool


@dataclass(frozen=True)
class FailRule:
    """Ends a trial at once as a failure, saying ``reason``."""

    when: Predicate
    reason: str


@dataclass(frozen=True)
class Outcome:
    """How a trial of the task is judged.

    Attributes
    ----------
    done : Predicate
        The task is over (then judged by ``success``).
    success : Predicate
        Whether it succeeded, asked once it is done.
    done_reason : str
        What a trial's end says when it was done (``poured``, ``opened``).
    fail : tuple of FailRule
        What ends it early as a failure, in order.
    progress : Reading
        How much of the task is done (the trial's ``progress``).
    clock : Predicate
        The completion clock starts when this first holds.
    time_limit : float
        s after which a trial is a failure.
    """

    done: Predicate
    success: Predicate
    done_reason: str
    fail: tuple[FailRule, ...]
    progress: Reading
    clock: Predicate
    time_limit: float


# -- the intent ------------------------------------------------------------------------
DONE = "done"
"""The phase after the intent's last step (no step may be called so)."""


@dataclass(frozen=True)
class Step:
    """One sub-goal of the intent: its ``name`` (the phase the evaluation reports) and
    what it does, a step of a registered kind (:class:`~sctd.task.kinds.StepKind`: a
    reach, a tilt, an upright, a joint's move, a press, a grasp, ...)."""

    name: str
    action: StepKind


# -- how demonstrations vary ---------------------------------------------------------------
@dataclass(frozen=True)
class TeachStep:
    """How a person's demonstrations vary one step of the intent (``sctd teach``).

    Attributes
    ----------
    yaw : float
        A reach: the hand's orientation turned about the vertical within this either way,
        rad (towards a point goal the hand faces the task object's vertical axis from where
        it starts; towards a handle it starts so turned from the handle's orientation and
        takes the handle's on the way).
    height : tuple of float or None
        A reach to a point (``to``): the goal's height in the task object's frame drawn
        from this range, m (None: the goal's own).
    to : tuple of float or None
        A tilt: the tilt drawn from this range, rad; a joint's move: the position it is
        moved to drawn from this range (m or rad). None: the step's own target.
    miss : float
        A reach: how far a mistaken demonstration misses its goal, m (a point goal in a
        random horizontal direction, a handle to its side, along its y); a press: how far
        beside the button's centre it pushes (along the body's y).
    margin : tuple of float or None
        A press: how far past the button's click depth the frame is pushed, m, drawn
        from this range (None: :data:`PRESS_MARGIN`).
    """

    yaw: float = 0.0
    height: tuple[float, float] | None = None
    to: tuple[float, float] | None = None
    miss: float = 0.05
    margin: tuple[float, float] | None = None


PRESS_MARGIN = (0.002, 0.004)
"""m past a button's click depth a demonstration pushes its frame when the task's
``teach`` section does not say (the arm and the contact yield a little under the push)."""


@dataclass(frozen=True)
class Teach:
    """How a person's demonstrations of the task vary, and how fast they go.

    Attributes
    ----------
    start : float
        The hand starts within this of the scene's start position, each axis, m.
    start_height : tuple of float or None
        The start's height within these offsets instead (None: +-``start``), m.
    via : float
        Each reach bends through a via point within this of the straight path, along each
        of the two directions across it, m.
    via_at : tuple of float
        Where along the path the via point lies (fractions of it).
    speed : float
        A demonstration's speeds are the nominal ones times a factor within this of 1.
    reach_speed : float
        Mean speed of a reach, m/s.
    turn_rate : float
        Mean turn rate of a reach's change of orientation, rad/s.
    tilt_rate : float
        Mean turn rate of a tilt, rad/s.
    joint_speed : float
        Mean speed of the handle along its path while moving a joint, m/s.
    press_speed : float
        Mean speed of a frame pushing a button in, m/s.
    steps : dict of str to TeachStep
        By the intent step's name; a step not named varies by :class:`TeachStep`'s
        defaults.
    """

    start: float = 0.10
    start_height: tuple[float, float] | None = None
    via: float = 0.03
    via_at: tuple[float, float] = (0.35, 0.65)
    speed: float = 0.30
    reach_speed: float = 0.10
    turn_rate: float = 0.6
    tilt_rate: float = 0.65
    joint_speed: float = 0.08
    press_speed: float = 0.02
    steps: dict[str, TeachStep] = field(default_factory=dict)

    def step(self, name: str) -> TeachStep:
        """How the step ``name`` varies."""
        return self.steps.get(name, TeachStep())


@dataclass(frozen=True)
class Task:
    """A task, as its file says it.

    Attributes
    ----------
    name : str
        What goes on ``sctd/<robot>/demos/<name>/...`` and in learner requests.
    title, description, source : str
        A short title, what the task is, and where it comes from (a task list, a paper).
    object : str
        The task object: the body whose frame demonstrations and skills are in.
    scene : Scene
    outcome : Outcome
    intent : tuple of Step
        What a person doing it wants, in order (done after the last).
    teach : Teach
        How a person's demonstrations of it vary.
    parts : tuple of Task
        A task composed of several (:func:`sctd.task.compose.compose`): each as placed
        in the room, the first the one this task's outcome and intent are; empty for a
        task of one file.
    file : str
        Where it was read from (for messages).
    """

    name: str
    title: str
    description: str
    source: str
    object: str
    scene: Scene
    outcome: Outcome
    intent: tuple[Step, ...]
    teach: Teach = field(default_factory=Teach)
    file: str = ""
    parts: tuple[Task, ...] = ()
