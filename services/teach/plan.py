"""What each demonstration will be: the variation a person shows, seeded (pure numpy).

A person teaching a task by hand never shows it twice the same way. Between
demonstrations (the ranges of :class:`Variation`) the hand starts elsewhere
(within +-10 cm of the scene's start, each axis), its path bends through a different
via point, it moves faster or slower (+-30 %), and a pour tilts the bottle about an
axis turned by up to +-0.3 rad of yaw from facing the mug, with the opening 3-6 cm
above the mug's.

Everything is planned in the task object's frame (``T_obj_ee``; the scenes'
conventions, :mod:`sctd_sim.scenes`):

``pour`` (object ``mug``: origin at the centre of its opening, z up, x towards the
robot; the bottle's opening, the tip, 0.12 m along the hand's z). *carry*: the bottle,
upright, the hand facing the mug from where it starts (its x towards the mug's axis, as
at the scene's start) and turned by the pour yaw, is translated from the start through the via point
until its opening is over the mug's centre at the pour height; *pour*: the hand turns
about the tip's y axis (the hand's), tilting the bottle's top towards the mug, to the
planned tilt, until the mug holds the fill target.

``drawer`` (object ``drawer_handle``: the closed handle's grasp point, x out of the
drawer, z up). *reach*: from the start, the hand turned by a small yaw, through the via
point to the handle, turning to the handle's orientation on the way (it grasps when it
comes within the grasp radius); *pull*: along +x by the planned length.

This is the shape of the generated demonstrations the learners were tuned on
(:mod:`sctd_sim.demogen`): a translation, then a rotation about the tip or a pull.
:func:`plan_demonstration` is a pure function of the scene, the seed and the attempt's
number: the same seed gives the same variations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sctd import se3
from sctd.task import find_task

Array = NDArray[np.float64]

TASK_OBJECT = {"pour": "mug", "drawer": "drawer_handle"}
"""The task object of each scene (the frame demonstrations are recorded in)."""

MISTAKE_OFF_AXIS = {"pour": 0.06, "drawer": 0.05}
"""m: how far a mistaken demonstration misses (pour: the opening that far off the mug's
axis, beyond its 4 cm rim, so it spills; drawer: the hand that far beside the handle,
beyond its 2 cm grasp radius, so it never grasps)."""


@dataclass(frozen=True)
class Variation:
    """How much demonstrations differ from each other, as a person's do.

    Attributes
    ----------
    start : float
        The hand starts within this of the scene's start position, each axis, m.
    pour_start_height : tuple of float
        Pour: the start's height within these offsets from the scene's start instead, m:
        no higher than the scene's start (the opening 15 cm above the mug's), as a full
        bottle is lifted no higher than needed. (Starts above it make the carry's
        mean direction, the learned translation field, steep enough that near the mug a
        user's push tips the bottle's opening down into it.)
    via : float
        The via point lies within this of the straight path, along each of the two
        directions across it, m.
    via_at : tuple of float
        Where along the path the via point lies (fractions of it).
    speed : float
        Speeds within this fraction of the nominal ones (:class:`Speeds`), either way.
    pour_yaw : float
        The pour axis (the hand's y, the bottle carried upright) turned about the vertical
        within this of facing the mug from the start (the hand's x towards the mug's
        axis, as at the scene's start), rad.
    pour_height : tuple of float
        The bottle's opening above the mug's while pouring, m.
    pour_tilt : tuple of float
        The tilt the bottle turns to, rad (it flows past 75 deg, 1.31 rad).
    reach_yaw : float
        The hand's start orientation turned about the vertical within this of the
        handle's, rad (it turns to the handle's on the way).
    pull : tuple of float
        How far the drawer is pulled, m (success is 0.20 m).
    """

    start: float = 0.10
    pour_start_height: tuple[float, float] = (-0.10, 0.0)
    via: float = 0.03
    via_at: tuple[float, float] = (0.35, 0.65)
    speed: float = 0.30
    pour_yaw: float = 0.30
    pour_height: tuple[float, float] = (0.03, 0.06)
    pour_tilt: tuple[float, float] = (math.radians(100.0), math.radians(120.0))
    reach_yaw: float = 0.25
    pull: tuple[float, float] = (0.23, 0.28)


@dataclass(frozen=True)
class Speeds:
    """Nominal speeds of a demonstration (each one's are these times its ``speed``), and
    of the unrecorded moves between demonstrations.

    Attributes
    ----------
    carry, reach, pull : float
        Mean speeds of the hand, m/s.
    pour : float
        Mean turn rate of the pour, rad/s.
    move, turn : float
        Mean speed (m/s) and turn rate (rad/s) of the moves between demonstrations.
    """

    carry: float = 0.10
    reach: float = 0.10
    pull: float = 0.08
    pour: float = 0.65
    move: float = 0.12
    turn: float = 0.6


@dataclass(frozen=True)
class SceneGeometry:
    """What planning needs to know about a scene, in the task object's frame.

    Attributes
    ----------
    task : str
    T_obj_start : ndarray, shape (4, 4)
        The scene's start pose of the hand.
    T_ee_tip : ndarray, shape (4, 4)
        The bottle's opening in the hand's frame (pour; identity for the drawer).
    """

    task: str
    T_obj_start: Array
    T_ee_tip: Array


def scene_geometry(task: str) -> SceneGeometry:
    """The geometry of the task ``task`` (a name or a file, :func:`sctd.task.find_task`),
    from its file's defaults: the start pose relative to the task object does not change
    when the object stands elsewhere. ``T_ee_tip`` is the held object's outlet (the frame
    its contents flow out of), else the hand's own frame.

    Raises
    ------
    sctd.task.TaskError
        Unknown task, or a task file that does not validate.
    """
    t = find_task(task)
    T_world_obj = t.scene.bodies[t.object].T_world
    held = t.scene.held
    outlet = held is not None and held.contents is not None
    T_ee_tip = held.frames[held.contents.outlet] if outlet else np.eye(4)  # type: ignore[union-attr]
    return SceneGeometry(t.name, se3.invert_transform(T_world_obj) @ t.scene.start.T_world, T_ee_tip.copy())


@dataclass(frozen=True)
class DemoPlan:
    """One demonstration as planned (object frame, SI units).

    Attributes
    ----------
    task : str
    attempt : int
        Its number among the attempts (from 1).
    T_obj_start : ndarray, shape (4, 4)
        The hand where the demonstration starts.
    via : ndarray, shape (3,)
        The hand's via point.
    via_at : float
        Where along the path it lies (the fraction of the straight path it is off).
    T_obj_goal : ndarray, shape (4, 4)
        The hand where the carry or reach ends (pour: the opening at the pour point,
        the bottle upright; drawer: at the handle, in its orientation).
    speed : float
        Factor on the nominal speeds.
    yaw : float
        Pour: the pour axis' yaw from facing the mug from the start; drawer: the start
        orientation's from the handle's (rad).
    height : float
        Pour: the bottle's opening above the mug's while pouring, m (0 for the drawer).
    tilt : float
        Pour: the tilt the bottle turns to, rad (0 for the drawer).
    pull : float
        Drawer: how far it is pulled, m (0 for the pour).
    mistake : bool
        Whether the demonstrator errs in it (:data:`MISTAKE_OFF_AXIS`).
    """

    task: str
    attempt: int
    T_obj_start: Array
    via: Array
    via_at: float
    T_obj_goal: Array
    speed: float
    yaw: float
    height: float
    tilt: float
    pull: float
    mistake: bool

    def describe(self) -> str:
        """One line: what varies in it."""
        p = self.T_obj_start[:3, 3]
        text = f"start ({p[0]:+.3f}, {p[1]:+.3f}, {p[2]:+.3f}) m, speed x{self.speed:.2f}"
        if self.task == "pour":
            text += f", yaw {self.yaw:+.2f} rad, height {self.height:.3f} m, tilt " \
                    f"{math.degrees(self.tilt):.0f} deg"
        else:
            text += f", yaw {self.yaw:+.2f} rad, pull {self.pull:.3f} m"
        return text + (", a mistake" if self.mistake else "")


def plan_demonstration(geometry: SceneGeometry, seed: int, attempt: int,
                       variation: Variation = Variation(), mistake: bool = False) -> DemoPlan:
    """The seeded variation of attempt ``attempt`` (from 1) of a session seeded ``seed``.

    A pure function: its random numbers come from ``numpy.random.default_rng([seed,
    attempt])``, so the same seed gives the same plans, attempt by attempt, whatever
    came of the earlier attempts.

    Parameters
    ----------
    geometry : SceneGeometry
    seed, attempt : int
    variation : Variation
    mistake : bool
        Plan the demonstrator's mistake: the pour's opening or the reaching hand
        :data:`MISTAKE_OFF_AXIS` off where it should be.
    """
    if attempt < 1:
        raise ValueError(f"attempt: must be >= 1, got {attempt}")
    rng = np.random.default_rng([seed, attempt])
    V = variation
    speed = 1.0 + float(rng.uniform(-V.speed, V.speed))
    T_start = geometry.T_obj_start.copy()
    low, high = [-V.start, -V.start, -V.start], [V.start, V.start, V.start]
    if geometry.task == "pour":
        low[2], high[2] = V.pour_start_height
    T_start[:3, 3] += rng.uniform(low, high)
    if geometry.task == "pour":
        yaw = float(rng.uniform(-V.pour_yaw, V.pour_yaw))
        R = facing(T_start[:3, 3], geometry) @ se3.matrix_from_rotvec([0.0, 0.0, yaw])
        T_start[:3, :3] = R
        tip = np.array([0.0, 0.0, rng.uniform(*V.pour_height)])
        miss = _horizontal(rng) * MISTAKE_OFF_AXIS["pour"]  # drawn always: a mistake changes
        if mistake:  # nothing else
            tip[:2] = miss
        T_goal = se3.transform_from_rt(R, tip - R @ geometry.T_ee_tip[:3, 3])
        height, tilt, pull = float(tip[2]), float(rng.uniform(*V.pour_tilt)), 0.0
    else:
        yaw = float(rng.uniform(-V.reach_yaw, V.reach_yaw))
        T_start[:3, :3] = geometry.T_obj_start[:3, :3] @ se3.matrix_from_rotvec([0.0, 0.0, yaw])
        miss = np.array([0.0, MISTAKE_OFF_AXIS["drawer"] * rng.choice([-1.0, 1.0]), 0.0])
        T_goal = se3.transform_from_rt(np.eye(3), miss if mistake else np.zeros(3))
        height, tilt, pull = 0.0, 0.0, float(rng.uniform(*V.pull))
    via, via_at = _via_point(T_start[:3, 3], T_goal[:3, 3], rng, V)
    return DemoPlan(geometry.task, attempt, T_start, via, via_at, T_goal, speed, yaw, height,
                    tilt, pull, mistake)


def facing(p_obj_ee: Array, geometry: SceneGeometry) -> Array:
    """The scene's start orientation turned about the vertical so that the hand at
    ``p_obj_ee`` (object frame) faces the object's vertical axis as the scene's start
    faces it (pour: the hand's x towards the mug), shape (3, 3). Spreading the pour
    planes so (the pour in each demonstration turns about a differently yawed axis)
    is what lets a learner tell a sphere about the opening from a cylinder."""
    p0 = geometry.T_obj_start[:3, 3]
    turn = math.atan2(-p_obj_ee[1], -p_obj_ee[0]) - math.atan2(-p0[1], -p0[0])
    return se3.matrix_from_rotvec([0.0, 0.0, turn]) @ geometry.T_obj_start[:3, :3]


def _horizontal(rng: np.random.Generator) -> Array:
    a = float(rng.uniform(-math.pi, math.pi))
    return np.array([math.cos(a), math.sin(a)])


def _via_point(a: Array, b: Array, rng: np.random.Generator, V: Variation) -> tuple[Array, float]:
    """A point a fraction ``f`` (within ``via_at``) of the way from ``a`` to ``b``, off the
    straight path by up to ``via`` along its horizontal normal and along the normal in
    the vertical plane; (point, f)."""
    d = (b - a) / max(float(np.linalg.norm(b - a)), 1e-9)
    side = np.cross([0.0, 0.0, 1.0], d)
    if float(np.linalg.norm(side)) < 1e-6:  # a vertical path: any horizontal direction
        side = np.array([1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    up = np.cross(d, side)
    f = float(rng.uniform(*V.via_at))
    off = rng.uniform(-V.via, V.via, 2)
    return a + f * (b - a) + off[0] * side + off[1] * up, f
