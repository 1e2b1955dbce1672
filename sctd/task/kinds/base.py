"""What a kind of task element is: the classes a kind subclasses, and what its parts are
given (pure: no I/O)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np
from numpy.typing import NDArray

from sctd import se3

if TYPE_CHECKING:  # (typing only: the reader imports the registry)
    from ..model import Outcome, Scene, Step, Task, TeachStep
    from .teaching import Draft, StepPlan

Array = NDArray[np.float64]


# -- the simulator's side ---------------------------------------------------------------
class Fingers(Protocol):
    """The hand's two fingers as a facet's physics sees them (the simulator's hand).

    ``width`` is the opening between the fingertips (m), ``closing`` whether the newest
    command closes them (a grasp: until they meet something, squeezing at most
    ``force`` N), ``max_width`` their widest opening. The fingers close along the hand's y
    axis, their tips' middle at the hand's origin."""

    width: float
    max_width: float
    closing: bool
    force: float

    def block(self, width: float) -> None:
        """Something between the fingers stops them at ``width`` this step (they hold it)."""


@dataclass
class World:
    """What a facet's physics sees at one step.

    Attributes
    ----------
    T_world_ee : ndarray (4, 4)
        The hand.
    twist : ndarray (6,)
        Its twist [v, w] (world axes, at its origin).
    poses : dict of str to ndarray (4, 4)
        Every body's pose now: a physics that moves its body (an item carried) writes its
        own entry.
    fingers : Fingers or None
        The hand's fingers; None for a hand without.
    physics : dict of str to dict of str to FacetPhysics
        Every facet's physics, by body and key, and every section entry's, by its name
        and its section's key: what one facet asks of another (an item asks the supports
        where it can rest).
    """

    T_world_ee: Array
    twist: Array
    poses: dict[str, Array]
    fingers: Fingers | None = None
    physics: dict[str, dict[str, FacetPhysics]] = field(default_factory=dict)


class FacetPhysics(ABC):
    """A facet's physics in the simulator, one per body that has it."""

    @abstractmethod
    def reset(self, world: World) -> None:
        """Back to the trial's start (the bodies where ``world.poses`` puts them)."""

    @abstractmethod
    def step(self, world: World, dt: float) -> Array:
        """Advance by ``dt``; the wrench (6,) it exerts on the hand (world axes, at its
        origin; N and N m)."""

    @abstractmethod
    def readings(self, world: World) -> dict[str, float | bool]:
        """Its readings, ``<body>.<quantity>``."""

    def load(self) -> tuple[float, Array] | None:
        """What the hand carries of it: mass (kg) and centre of mass in the hand's frame;
        None for nothing."""
        return None

    def frames(self, world: World) -> dict[str, Array]:
        """Frames it publishes besides its body's (world, 4x4)."""
        return {}

    def held_mass(self) -> float:
        """kg it adds to the object the hand holds from the start, at that object's centre
        of mass (what is left of its contents); 0 by default."""
        return 0.0

    def outcome(self, world: World, thresholds: dict[str, float]) -> dict[str, Any]:
        """Fields of its own for the scene's outcome (a joint's ``opening``), given the
        task's thresholds; none by default."""
        return {}


@dataclass(frozen=True)
class Shape:
    """A solid to draw, in its body's frame: a ``box`` of full ``size`` (x, y, z), a
    ``cylinder`` of ``size`` (radius, radius, height) about its z or a ``sphere`` of
    ``size`` (radius, radius, radius), centred at ``T_body_shape``'s origin; ``colour``
    RGB in [0, 1]; ``name`` what the view calls its part (``<element>/<name>``; empty:
    named after its kind and place), ``label`` what it shows as its label (``{body}``
    standing for its body's name; empty: the body and the kind)."""

    kind: str
    size: tuple[float, float, float]
    T_body_shape: Array
    colour: tuple[float, float, float] = (0.6, 0.6, 0.6)
    opacity: float = 1.0
    name: str = ""
    label: str = ""


# -- kinds -------------------------------------------------------------------------------
class Facet(ABC):
    """A kind of scene element a body has: ``bodies.<name>.<key>`` in a task file.

    Class attributes
    ----------------
    key : str
        Its field in a body's mapping (or in the held object's).
    holder : str
        ``body`` (a facet of a body, ``bodies.<name>.<key>``) or ``held`` (of the object
        the hand holds from the start, ``held.<key>``: its contents; its readings are the
        held object's, ``<held>.<quantity>``).
    order : int
        Facets are read and stepped in this order (one that refers to another comes after it).
    quantities : tuple of str
        Its readings, ``<body>.<quantity>``; empty for none.
    flags : tuple of str
        Those of them that are true or false.
    angular : tuple of str
        Those that are angles (a task file may write their bounds in degrees).
    """

    key: ClassVar[str]
    holder: ClassVar[str] = "body"
    order: ClassVar[int] = 0
    quantities: ClassVar[tuple[str, ...]] = ()
    flags: ClassVar[tuple[str, ...]] = ()
    angular: ClassVar[tuple[str, ...]] = ()

    @classmethod
    @abstractmethod
    def read(cls, r: Any, v: Any, path: str) -> Facet:
        """The facet a task file's field ``v`` at ``path`` says (``r``: the task reader,
        whose ``fail(path, problem)`` is the error to raise)."""

    def completed(self, r: Any, body: str, scene: Scene, path: str) -> Facet:
        """The facet with what it takes from the rest of the scene filled in, once the
        bodies and the held object are read (``body``: its holder's name; ``scene``: them;
        a surface's ``touch`` defaults to every frame that moves with the hand; the
        contents' outlet and container are checked); itself by default."""
        return self

    def check(self, r: Any, body: str, scene: Scene, path: str) -> None:  # noqa: B027 - most check nothing
        """Cross-checks once the whole scene is read (what it names exists)."""

    @abstractmethod
    def to_yaml(self) -> dict[str, Any]:
        """Its task-file field: :meth:`read` gives the same facet back."""

    def frame_names(self) -> list[str]:
        """The frames it publishes besides its body's (its physics' :meth:`FacetPhysics.frames`)."""
        return []

    def physics(self, body: str, scene: Scene) -> FacetPhysics | None:
        """Its physics in the simulator; None for a facet the simulator has nothing to do for."""
        return None

    def shapes(self) -> list[Shape]:
        """What the view draws of it, in its body's frame."""
        return []

    def extent(self) -> float:
        """How far it reaches around its body's origin, m, in a room of several tasks
        (a container's radius); 0 by default."""
        return 0.0


class Section(ABC):
    """A kind of scene element that is an entry of a section of the scene of its own,
    ``scene.<key>.<name>`` in a task file (a joint: ``scene.joints.drawer``; a person's
    head: ``scene.heads.face``), rather than a facet of one body. Its readings are
    ``<name>.<quantity>``; the name shares the scene's one namespace (bodies, held
    frames, every section's entries, ``hand``).

    Class attributes
    ----------------
    key : str
        The scene's field it is read from (``heads``); a section in a file holds at least
        one entry.
    noun : str
        What one entry is called in messages (``head``: ``a head reports force, ...``).
    order : int
        Sections are read, checked and stepped in this order (one that refers to another
        comes after it): after the held object's facets, before the bodies' facets.
    quantities, flags, angular : tuple of str
        As a :class:`Facet`'s, of ``<name>.<quantity>``.

    Attributes
    ----------
    name : str
        Its entry's name in the section.
    """

    key: ClassVar[str]
    noun: ClassVar[str]
    order: ClassVar[int] = 0
    quantities: ClassVar[tuple[str, ...]] = ()
    flags: ClassVar[tuple[str, ...]] = ()
    angular: ClassVar[tuple[str, ...]] = ()

    name: str

    @classmethod
    @abstractmethod
    def read(cls, r: Any, name: str, v: Any, path: str, scene: Scene) -> Section:
        """The entry ``name`` a task file's field ``v`` at ``path`` says; ``scene`` is the
        scene read so far (its start, bodies, held object and the sections before this
        one)."""

    def check(self, r: Any, scene: Scene, path: str) -> None:  # noqa: B027 - most check nothing
        """Cross-checks once the whole scene is read (``path``: the scene's)."""

    def check_intent(self, r: Any, scene: Scene, obj: str, intent: tuple[Step, ...]) -> None:  # noqa: B027
        """Cross-checks of the intent against it, once read (``obj``: the task object)."""

    @abstractmethod
    def to_yaml(self) -> dict[str, Any]:
        """Its entry's fields: :meth:`read` gives the same element back."""

    def physics(self, scene: Scene) -> FacetPhysics | None:
        """Its physics in the simulator (its readings by its ``name``); None for none."""
        return None

    def is_angular(self, quantity: str) -> bool:
        """Whether its reading ``quantity`` is an angle (a file may write its bounds in
        degrees): those in :attr:`angular`, unless the entry says otherwise."""
        return quantity in self.angular

    def body(self) -> str | None:
        """The body its drawing moves with (None: drawn nowhere)."""
        return None

    def label(self) -> str:
        """What the view calls it."""
        return self.name

    def drawn_at(self, T_world: dict[str, Array], readings: dict[str, Any]) -> Array | None:
        """Where its shapes are drawn (world, 4x4), the bodies at ``T_world`` and the
        scene's ``readings`` as given: :meth:`body`'s pose (a joint's: its handle where
        the joint has moved it); None when not known."""
        body = self.body()
        return None if body is None else T_world.get(body)

    def shapes(self) -> list[Shape]:
        """What the view draws of it, in the frame :meth:`drawn_at` gives."""
        return []

    def footprint(self, scene: Scene) -> list[tuple[Array, float]]:
        """Balls (centre in the world, radius) it takes up, at the file's poses: where
        another task composed into the room must not come (:func:`sctd.task.compose.compose`)."""
        return []


@dataclass
class Sight:
    """What the simulated person sees at a step: the hand and the published frames
    (world, 4x4), the scene's readings, and the frames' positions (``hand`` among them)."""

    T_world_ee: Array
    objects: Mapping[str, Array]
    readings: Mapping[str, Any]
    positions: Mapping[str, Array]
    memo: dict[Any, Any] = field(default_factory=dict)
    """What the minds worked out of this sight for one another, by a key of their own (a
    reach's view of its goal, which the tilt after it shares): worked out once a look."""


@dataclass
class Want:
    """What the person wants of the hand at a step: ``twist`` [v, w] (world, at the hand's
    origin), ``W`` (6, 6) the weights of its errors (a map from the hand's twist), and what
    the fingers should do: ``close``, ``open`` or None (as they are)."""

    twist: Array
    W: Array
    grip: str | None = None


class Person(Protocol):
    """How a simulated person moves (:class:`sctd_services.user.intent.TaskIntent` is one,
    whose doc says what each is)."""

    gain: float
    v_max: float
    w_max: float
    free_weight: float
    per_rad: float
    lean: float
    ahead: float
    past: float
    press_speed: float
    slow: float
    clearance: float
    aim: float


class Run:
    """What the minds of one run of a task's intent share (one simulated person's).

    Attributes
    ----------
    task : Task
    person : Person
    minds : list of StepMind
        The steps' minds by index, as they are made, in order: a step's mind is made
        with those of the steps before it here (a tilt's finds the reach whose frame it
        moves).
    wanted : int
        The step whose :meth:`StepMind.want` was asked last (-1: none yet): a mind that
        keeps a choice while its step is wanted look after look (a tilt's axis) makes it
        again when another step was wanted in between.
    """

    def __init__(self, task: Task, person: Person):
        self.task, self.person = task, person
        self.minds: list[StepMind] = []
        self.wanted = -1
        self._inverses: dict[str, tuple[bytes, Array]] = {}

    @property
    def scene(self) -> Scene:
        return self.task.scene

    @property
    def steps(self) -> tuple[Step, ...]:
        return self.task.intent

    def inverse(self, name: str, T: Array) -> Array:
        """``T`` (4, 4) inverted, worked out again only when the frame ``name`` moved (the
        minds of a run share it)."""
        key = T.tobytes()
        kept = self._inverses.get(name)
        if kept is None or kept[0] != key:
            kept = self._inverses[name] = (key, se3.invert_transform(T))
        return kept[1]


class StepMind(ABC):
    """A simulated person's behaviour for one intent step, for one run."""

    @abstractmethod
    def move(self, sight: Sight) -> int:
        """+1: the step is complete; -1: back to the step before; 0: stay."""

    @abstractmethod
    def error(self, sight: Sight) -> float:
        """How far from complete it is, m (and m-equivalents)."""

    @abstractmethod
    def want(self, sight: Sight) -> Want:
        """How the hand should move now, and the fingers."""

    def rest(self, sight: Sight) -> Want:
        """What the hand should do once the intent is done, this being its last step: stay
        still (no twist; by default every error weighed alike)."""
        return Want(np.zeros(6), np.eye(6))

    def close_enough(self, sight: Sight) -> bool:
        """Whether the step is short of complete but within what the task tolerates (a
        person who cannot get any closer may :meth:`settle`); False by default."""
        return False

    def settle(self) -> bool:
        """Whether a person who got no closer, :meth:`close_enough`, takes the step as done
        (then the intent goes on to the next); False by default."""
        return False


@dataclass(frozen=True)
class Leg:
    """One leg of a demonstration of a step: the hand to ``T_world_ee`` (world, as the
    demonstration's scene stands at its start), at ``speed`` times the task's reach speed
    and turn rate (slower coming onto a grip), then the fingers do ``grip`` (``close`` with
    ``force`` N, ``open``; None: nothing), then the demonstrator holds the hand still until
    the reading ``until[0]`` is ``until[1]`` (None: no wait)."""

    T_world_ee: Array
    speed: float = 1.0
    grip: str | None = None
    force: float | None = None
    until: tuple[str, bool] | None = None


@dataclass(frozen=True)
class Floor:
    """A step's part of a lower bound of the hand's path through a task with the scene at
    its defaults (a task's floor, ``sctd suite``).

    Attributes
    ----------
    points : tuple of ndarray (3,)
        The points (world, m) the frame must pass through, in order, straight from one to
        the next being the shortest way (from where the frame of the first step with
        points starts, or from the last point before).
    radians : float
        The radians it must turn at least.
    along : float
        m the hand must go besides, on a path of its own (a joint's handle along its
        path to the task's threshold).
    frame : str
        The frame whose points they are (``hand``, or a frame of what the hand holds):
        where the first step with points starts it is where the way starts.
    clock : str
        How a ``near`` clock shortens the way to the first point, given by the first
        step with points: ``body`` (the clock starts on the sphere about its body's
        origin: at least ``within`` less the point's distance from it away) or ``goal``
        (on a clock about the task object, at most ``within`` from the point).
    """

    points: tuple[Array, ...] = ()
    radians: float = 0.0
    along: float = 0.0
    frame: str = "hand"
    clock: str = "body"


class StepKind(ABC):
    """A kind of intent step: ``intent[i].<key>`` in a task file.

    Class attributes
    ----------------
    key : str
        Its field in a step's mapping.
    grips : bool
        Whether the step works the fingers (a person doing it uses the grasp button).
    finish : bool
        Whether it finishes the task once it is shown (a frame brought upright after a
        pour): a demonstration does not record it when only such steps come after it.
    teaches : tuple of str or None
        The fields of :class:`~sctd.task.model.TeachStep` a task's ``teach.steps.<name>``
        may give a step of this kind (``yaw``, ``height``, ``to``, ``miss``, ``margin``;
        those of them a kind reads itself, :meth:`read_teach`); None: the step may not be
        named there.
    """

    key: ClassVar[str]
    grips: ClassVar[bool] = False
    finish: ClassVar[bool] = False
    teaches: ClassVar[tuple[str, ...] | None] = None

    @classmethod
    @abstractmethod
    def read(cls, r: Any, v: Any, path: str, scene: Scene, outcome: Outcome,
             before: tuple[Step, ...]) -> StepKind:
        """The step a task file's field ``v`` at ``path`` says (``before``: the intent's
        steps read before it; a tilt moves the frame of the reach before it)."""

    @abstractmethod
    def to_yaml(self, scene: Scene) -> dict[str, Any]:
        """Its task-file field: :meth:`read` gives the same step back (``scene``: the
        task's, which says whether a predicate's bound is an angle)."""

    def read_teach(self, r: Any, d: dict[str, Any], path: str, scene: Scene) -> dict[str, Any]:
        """The fields of its :class:`~sctd.task.model.TeachStep` that its kind reads from
        ``d`` (``teach.steps.<name>``, its keys among :attr:`teaches`): a reach's goal
        ``height``, a tilt's ``to``; the reader reads ``yaw``, ``miss`` and ``margin``. None
        by default."""
        return {}

    def teach_to_yaml(self, ts: TeachStep, scene: Scene) -> dict[str, Any]:
        """The fields :meth:`read_teach` reads, as a task file writes them; none by default."""
        return {}

    @abstractmethod
    def frame(self) -> str:
        """The frame the step moves (``hand``, or a frame of what the hand holds)."""

    @abstractmethod
    def mind(self, run: Run, index: int) -> StepMind:
        """The simulated person's behaviour for it, as step ``index`` of ``run`` (whose
        minds hold those of the steps before it)."""

    @abstractmethod
    def floor_path(self, task: Task, before: tuple[Floor, ...]) -> Floor:
        """Its part of a lower bound of the hand's path through ``task`` with its scene at
        its defaults (:class:`Floor`; ``before``: the parts of the steps before it)."""

    def legs(self, scene: Scene, poses: Mapping[str, Array], T_world_ee: Array, rng: np.random.Generator,
             mistake: bool = False) -> list[Leg]:
        """A demonstration of it (``sctd teach``) as the default :meth:`plan` shows it: the
        hand's legs from ``T_world_ee`` with the bodies at ``poses`` (world), varied by
        ``rng`` as a person's demonstrations vary; with ``mistake``, the way a person gets
        it wrong (a grasp beside the item). None by default (a kind that plans its
        demonstration otherwise)."""
        return []

    def plan(self, draft: Draft, rng: np.random.Generator) -> StepPlan:
        """How a demonstration shows it (``sctd teach``), its variations drawn from ``rng``
        (the plan's, in the intent's order: draw nothing more than the step needs, always
        the same draws). By default by its :meth:`legs`, drawn from a seed drawn here."""
        from .teaching import StepPlan  # (the plan's data)

        return StepPlan(draft.name, self.key, self.frame(), draw=int(rng.integers(2**31)))
