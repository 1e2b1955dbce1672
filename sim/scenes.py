"""Task scenes: what the arm interacts with and how well the task went (pure logic).

A scene is stepped once per cycle with the true ee pose and twist; it returns the
external wrench it exerts on the ee (world axes at the ee origin, N and N m), names
its objects' poses, and scores the task. No Pinocchio, bus or Zenoh here.

``pour``
    A bottle held in the hand and a ``mug`` on the table (the task object: origin at
    the centre of the mug's opening, z up, x towards the robot). The ee z axis is the
    bottle's axis and its opening, ``bottle_tip``, sits 0.12 m along it (as in
    :mod:`sctd_sim.demogen` and the shipped skill). Liquid flows while the bottle is
    tilted past the pouring angle; it lands in the mug if the tip is over the opening,
    otherwise it is spilled.
``drawer``
    A drawer on a prismatic joint. Its ``drawer_handle`` (task object: origin at the
    grasp point of the *closed* drawer, x out of the drawer, z up; the published frame
    stays there, so opening shows as ee motion along +x, as in the demonstrations) is
    grasped when the ee comes within the grasp radius of the moving handle, which is
    then coupled to the ee by a stiff spring-damper; the drawer resists with a spring,
    viscous damping and Coulomb friction, and stops at its end stops.

World is the arm's base frame. The arm is mounted low (as on a wheelchair), so the
mug's opening is 0.65 m and the drawer handle 0.60 m above the base, 0.75 m in front:
where the demonstrations' motions (with the hand pointing up) stay in reach.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from sctd import se3

GRAVITY = 9.81


R_TOWARDS_ROBOT = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
"""Object orientation with x pointing back at the robot (world -x), z up."""


class Scene(Protocol):
    """What :class:`sctd_sim.simulation.Simulation` needs from a scene."""

    name: str
    task_object: str

    def reset(self) -> None:
        """Back to the initial state."""

    def start_pose(self) -> np.ndarray:
        """Suggested initial ``T_world_ee`` (4x4)."""

    def step(self, T_world_ee: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
        """Advance by ``dt``; return the wrench on the ee, shape (6,)."""

    def objects(self, T_world_ee: np.ndarray) -> dict[str, np.ndarray]:
        """Object poses ``T_world_obj`` (4x4) by name."""

    def outcome(self) -> dict[str, Any]:
        """Task outcome so far (plain JSON/msgpack types)."""

    def payload(self) -> tuple[float, np.ndarray] | None:
        """The load the arm carries as its controller is configured with it (a real arm's
        load data): mass (kg) and centre of mass in the ee frame (m); None for none."""


# -- pour -----------------------------------------------------------------------------
@dataclass
class PourParams:
    """Geometry and physics of the pouring scene (SI units).

    Attributes
    ----------
    T_world_mug : ndarray, shape (4, 4)
        Mug frame: centre of the opening, z up, x towards the robot.
    mug_radius, mug_height : float
        Inner radius of the opening and depth of the mug below it, m.
    rim_margin : float
        The tip counts as over the opening within ``mug_radius - rim_margin``.
    max_drop : float
        Highest tip height above the rim at which the stream still lands in the mug.
    T_ee_tip : ndarray, shape (4, 4)
        Bottle opening in the ee frame; its z axis is the bottle axis, out of the
        opening. Default: 0.12 m along ee z, axes as the ee's.
    pour_angle : float
        Tilt (angle between bottle axis and world up, rad) past which liquid flows.
    flow_rate : float
        Flow at 90 deg past the pouring angle, fraction of the content per second
        (flow grows as the sine of the tilt past the pouring angle).
    fill_target : float
        Fraction of the content that counts as a successful pour.
    bottle_mass_empty, liquid_mass : float
        Masses, kg; their weight acts at ``com_in_ee`` (m, ee frame).
    com_in_ee : ndarray, shape (3,)
    start_position : ndarray, shape (3,)
        Start position of the ee in world (orientation: bottle upright, ee x towards
        the mug).
    start_yaw : float
        Start orientation's turn about world z from ee x towards the mug, rad.
    """

    T_world_mug: np.ndarray = field(
        default_factory=lambda: se3.transform_from_rt(R_TOWARDS_ROBOT, [0.75, 0.0, 0.65]))
    mug_radius: float = 0.04
    mug_height: float = 0.10
    rim_margin: float = 0.005
    max_drop: float = 0.15
    T_ee_tip: np.ndarray = field(
        default_factory=lambda: se3.transform_from_rt(np.eye(3), [0.0, 0.0, 0.12]))
    pour_angle: float = math.radians(75.0)
    flow_rate: float = 0.6
    fill_target: float = 0.5
    bottle_mass_empty: float = 0.2
    liquid_mass: float = 0.3
    com_in_ee: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.05]))
    start_position: np.ndarray = field(default_factory=lambda: np.array([0.45, 0.0, 0.68]))
    start_yaw: float = 0.0


@dataclass(frozen=True)
class PourGeometry:
    """Where the bottle opening is relative to the mug.

    Attributes
    ----------
    tip_in_mug : ndarray, shape (3,)
        Bottle opening in the mug frame, m.
    tip_above_rim : float
        Height of the bottle opening above the mug's opening, m.
    radial : float
        Horizontal distance of the opening from the mug axis, m.
    tilt : float
        Angle between the bottle axis and world up, rad (0 upright, pi upside down).
    over_opening : bool
        Whether a stream from the tip lands inside the mug.
    """

    tip_in_mug: np.ndarray
    tip_above_rim: float
    radial: float
    tilt: float
    over_opening: bool


def pour_geometry(T_world_tip: np.ndarray, params: PourParams,
                  T_mug_world: np.ndarray | None = None) -> PourGeometry:
    """Bottle opening relative to the mug opening, and the bottle's tilt.

    ``T_mug_world``: the inverse of ``params.T_world_mug``, when the caller keeps it
    (the scene does: the mug does not move).
    """
    if T_mug_world is None:
        T_mug_world = se3.invert_transform(params.T_world_mug)
    p = (T_mug_world @ T_world_tip)[:3, 3]
    x, y, above = p.tolist()
    radial = math.hypot(x, y)
    tilt = math.acos(min(1.0, max(-1.0, float(T_world_tip[2, 2]))))
    over = radial <= params.mug_radius - params.rim_margin and 0.0 <= above <= params.max_drop
    return PourGeometry(p.copy(), above, radial, tilt, over)


def pour_flow(tilt: float, params: PourParams) -> float:
    """Flow out of the bottle at ``tilt`` (fraction of the full content per second)."""
    past = tilt - params.pour_angle
    if past <= 0.0:
        return 0.0
    return params.flow_rate * math.sin(min(past, math.pi / 2))


class PourScene:
    """Bottle in the hand, mug on the table.

    Parameters
    ----------
    params : PourParams, optional

    Attributes
    ----------
    remaining, poured, spilled : float
        Fractions of the bottle's content: still in the bottle, in the mug, spilled.
    """

    name = "pour"
    task_object = "mug"

    def __init__(self, params: PourParams | None = None) -> None:
        self.params = params or PourParams()
        self._mug_key = b""  # the T_world_mug (bytes) that _T_mug_world inverts
        self._T_mug_world = np.eye(4)
        self.reset()

    def reset(self) -> None:
        """Full bottle, nothing poured."""
        self.remaining = 1.0
        self.poured = 0.0
        self.spilled = 0.0
        self.geometry: PourGeometry | None = None

    def start_pose(self) -> np.ndarray:
        """Bottle upright, 0.3 m short of the mug, ee x towards it (turned by ``start_yaw``)."""
        R = se3.matrix_from_rotvec([0.0, 0.0, self.params.start_yaw])
        return se3.transform_from_rt(R, self.params.start_position)

    def tip_transform(self, T_world_ee: np.ndarray) -> np.ndarray:
        """``T_world_tip`` of the bottle opening."""
        return T_world_ee @ self.params.T_ee_tip

    def step(self, T_world_ee: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
        """Pour for ``dt`` seconds; return the bottle's weight as a wrench on the ee."""
        P = self.params
        g = self.geometry = pour_geometry(self.tip_transform(T_world_ee), P, self._mug_inverse())
        out = min(self.remaining, pour_flow(g.tilt, P) * dt)
        if out > 0.0:
            self.remaining -= out
            if g.over_opening:
                self.poured += out
            else:
                self.spilled += out
        fz = -(P.bottle_mass_empty + P.liquid_mass * self.remaining) * GRAVITY
        r0, r1, _ = T_world_ee[:3, :3].dot(P.com_in_ee).tolist()
        # [force, r x force] with force = (0, 0, fz), written out (np.cross costs ~25 us)
        return np.array((0.0, 0.0, fz, r1 * fz, -r0 * fz, 0.0))

    def _mug_inverse(self) -> np.ndarray:
        """``T_mug_world``, computed again only when the mug's pose changed."""
        T = self.params.T_world_mug
        key = T.tobytes()
        if key != self._mug_key:
            self._T_mug_world, self._mug_key = se3.invert_transform(T), key
        return self._T_mug_world

    def payload(self) -> tuple[float, np.ndarray] | None:
        """The bottle with what is left in it (the arm's load data follows it as it
        empties, as a real arm's load estimate from its force-torque sensing would)."""
        P = self.params
        return P.bottle_mass_empty + P.liquid_mass * self.remaining, P.com_in_ee

    def objects(self, T_world_ee: np.ndarray) -> dict[str, np.ndarray]:
        """``mug`` and ``bottle_tip``."""
        return {"mug": self.params.T_world_mug.copy(), "bottle_tip": self.tip_transform(T_world_ee)}

    def outcome(self) -> dict[str, Any]:
        """Tip relative to the mug, tilt, poured and spilled fractions, success."""
        g = self.geometry
        out: dict[str, Any] = {
            "scene": self.name,
            "poured": self.poured,
            "spilled_amount": self.spilled,
            "spilled": self.spilled > 1e-9,
            "remaining": self.remaining,
            "success": self.poured >= self.params.fill_target and self.spilled <= 1e-9,
            "fill_target": self.params.fill_target,
        }
        if g is not None:
            out.update(tip_in_mug=g.tip_in_mug.tolist(), tip_above_rim=g.tip_above_rim,
                       radial=g.radial, tilt=g.tilt, over_opening=g.over_opening,
                       pouring=pour_flow(g.tilt, self.params) > 0.0 and self.remaining > 0.0)
        return out


# -- drawer ---------------------------------------------------------------------------
@dataclass
class DrawerParams:
    """Geometry and physics of the drawer scene (SI units).

    Attributes
    ----------
    T_world_closed : ndarray, shape (4, 4)
        Handle frame with the drawer closed; x is the pull (opening) direction, out of
        the drawer, z up. This is the published ``drawer_handle``.
    max_opening : float
        Travel to the end stop, m.
    mass : float
        Moving mass, kg.
    stiffness : float
        Soft-close spring towards closed, N/m.
    damping : float
        Viscous damping, N s/m.
    friction : float
        Coulomb friction, N (smoothed over ``friction_speed``).
    friction_speed : float
        Speed, m/s, over which the friction force builds up (tanh).
    grasp_radius : float
        The handle is grasped when the ee comes this close, m.
    release_distance : float
        The grasp slips when the ee is pulled this far from the handle, m.
    coupling_stiffness, coupling_damping : float
        Spring (N/m) and damper (N s/m) between ee and grasped handle.
    success_opening : float
        Opening that counts as success, m.
    start_position : ndarray, shape (3,)
        Start position of the ee in world (orientation: the handle's).
    start_yaw : float
        Start orientation's turn about world z from the handle's, rad.
    """

    T_world_closed: np.ndarray = field(
        default_factory=lambda: se3.transform_from_rt(R_TOWARDS_ROBOT, [0.75, 0.0, 0.60]))
    max_opening: float = 0.30
    mass: float = 2.0
    stiffness: float = 30.0
    damping: float = 15.0
    friction: float = 3.0
    friction_speed: float = 0.01
    grasp_radius: float = 0.02
    release_distance: float = 0.06
    coupling_stiffness: float = 2000.0
    coupling_damping: float = 60.0
    success_opening: float = 0.20
    start_position: np.ndarray = field(default_factory=lambda: np.array([0.50, 0.0, 0.71]))
    start_yaw: float = 0.0


def drawer_force(opening: float, speed: float, params: DrawerParams) -> float:
    """Resistance of the drawer along its pull axis, N (negative: resists opening)."""
    return (-params.stiffness * opening - params.damping * speed
            - params.friction * math.tanh(speed / params.friction_speed))


class DrawerScene:
    """A drawer on a prismatic joint, opened by pulling its grasped handle.

    Attributes
    ----------
    opening : float
        Drawer travel from closed, m.
    speed : float
        Opening speed, m/s.
    attached : bool
        Whether the hand holds the handle.
    """

    name = "drawer"
    task_object = "drawer_handle"

    def __init__(self, params: DrawerParams | None = None) -> None:
        self.params = params or DrawerParams()
        self.reset()

    def reset(self) -> None:
        """Drawer closed and released."""
        self.opening = 0.0
        self.speed = 0.0
        self.attached = False
        self.max_opening_reached = 0.0
        self.grasps = 0

    def start_pose(self) -> np.ndarray:
        """Hand above and in front of the handle, in the handle's orientation."""
        R = se3.matrix_from_rotvec([0.0, 0.0, self.params.start_yaw]) @ self.params.T_world_closed[:3, :3]
        return se3.transform_from_rt(R, self.params.start_position)

    @property
    def axis(self) -> np.ndarray:
        """Pull direction in world, shape (3,)."""
        return self.params.T_world_closed[:3, 0].copy()

    def handle_transform(self) -> np.ndarray:
        """``T_world_handle`` at the current opening."""
        T = self.params.T_world_closed.copy()
        T[:3, 3] += self.opening * T[:3, 0]
        return T

    def step(self, T_world_ee: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
        """Grasp/release, move the drawer by ``dt``; return the wrench on the ee."""
        # (on floats: the same numbers as on 3-vectors, without numpy's per-call cost)
        P = self.params
        (ax, _, _, hx), (ay, _, _, hy), (az, _, _, hz), _ = P.T_world_closed.tolist()  # pull axis, handle
        o = self.opening
        (_, _, _, ex), (_, _, _, ey), (_, _, _, ez), _ = T_world_ee.tolist()
        dx, dy, dz = ex - (hx + o * ax), ey - (hy + o * ay), ez - (hz + o * az)
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        if not self.attached and dist <= P.grasp_radius:
            self.attached = True
            self.grasps += 1
        elif self.attached and dist > P.release_distance:
            self.attached = False
        fx = fy = fz = pull = 0.0  # force on the ee, and the pull along the axis
        if self.attached:
            k, c, s = P.coupling_stiffness, P.coupling_damping, self.speed
            vx, vy, vz = twist[:3].tolist()
            fx, fy, fz = (-k * dx - c * (vx - s * ax), -k * dy - c * (vy - s * ay),
                          -k * dz - c * (vz - s * az))
            pull = 0.0 + -fx * ax + -fy * ay + -fz * az  # (summed as numpy's dot sums)
        accel = (pull + drawer_force(self.opening, self.speed, P)) / P.mass
        self.speed += accel * dt
        self.opening += self.speed * dt
        if self.opening <= 0.0:
            self.opening, self.speed = 0.0, max(self.speed, 0.0)
        elif self.opening >= P.max_opening:
            self.opening, self.speed = P.max_opening, min(self.speed, 0.0)
        self.max_opening_reached = max(self.max_opening_reached, self.opening)
        return np.array((fx, fy, fz, 0.0, 0.0, 0.0))

    def objects(self, T_world_ee: np.ndarray) -> dict[str, np.ndarray]:
        """``drawer_handle``: the closed handle's frame (fixed, see the module doc)."""
        return {"drawer_handle": self.params.T_world_closed.copy()}

    def payload(self) -> tuple[float, np.ndarray] | None:
        """None: the hand holds the handle, the drawer is not a load it carries."""
        return None

    def outcome(self) -> dict[str, Any]:
        """Opening, whether the handle is held, success."""
        P = self.params
        return {
            "scene": self.name,
            "opening": self.opening,
            "open_fraction": self.opening / P.max_opening,
            "max_opening": self.max_opening_reached,
            "attached": self.attached,
            "grasps": self.grasps,
            "success": self.opening >= P.success_opening,
            "target_opening": P.success_opening,
        }


class EmptyScene:
    """No objects (benchmarks, controller tests)."""

    name = "empty"
    task_object = ""

    def reset(self) -> None:
        """Nothing to reset."""

    def start_pose(self) -> np.ndarray:
        """Hand in front, pointing down (the arm's rest posture's neighbourhood)."""
        return se3.transform_from_rt(np.diag([-1.0, 1.0, -1.0]), [0.55, 0.0, 0.20])

    def step(self, T_world_ee: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
        """No wrench."""
        return np.zeros(6)

    def objects(self, T_world_ee: np.ndarray) -> dict[str, np.ndarray]:
        """No objects."""
        return {}

    def payload(self) -> tuple[float, np.ndarray] | None:
        """No load."""
        return None

    def outcome(self) -> dict[str, Any]:
        """Nothing to score."""
        return {"scene": self.name}


SCENES = {"pour": PourScene, "drawer": DrawerScene, "empty": EmptyScene}
"""Scene classes by name."""


def make_scene(name: str, trial_seed: int | None = None, attempt: int = 0) -> Scene:
    """Scene by name (``pour``, ``drawer``, ``empty``); with ``trial_seed``, a seeded
    random start (:func:`randomize`; ``attempt`` draws another one for the same seed,
    for a start the arm cannot reach)."""
    try:
        scene = SCENES[name]()
    except KeyError:
        raise ValueError(f"scene: unknown {name!r}, expected one of {sorted(SCENES)}") from None
    if trial_seed is not None:
        randomize(scene, trial_seed, attempt)
    return scene


START_OFFSET = 0.10  # m: the hand starts within this of the scene's start, per axis
START_YAW = np.radians(15.0)  # rad: and within this of its start orientation's yaw
OBJECT_OFFSET = 0.05  # m: the task object stands within this of its default, per axis


def randomize(scene: Scene, seed: int, attempt: int = 0) -> None:
    """A seeded random start for an evaluation trial: the hand within +-START_OFFSET
    (each axis) and +-START_YAW of the scene's start, the task object within
    +-OBJECT_OFFSET of its default (on the table: horizontally for the mug)."""
    rng = np.random.default_rng([seed, attempt] if attempt else seed)
    P = getattr(scene, "params", None)
    if P is None:
        return
    scene.default_start_pose = scene.start_pose()  # type: ignore[attr-defined]  # (start_posture's via)
    P.start_position = P.start_position + rng.uniform(-START_OFFSET, START_OFFSET, 3)
    P.start_yaw = float(rng.uniform(-START_YAW, START_YAW))
    shift = rng.uniform(-OBJECT_OFFSET, OBJECT_OFFSET, 3)
    if isinstance(P, PourParams):
        shift[2] = 0.0  # the mug stands on the table
        P.T_world_mug = P.T_world_mug.copy()
        P.T_world_mug[:3, 3] += shift
    elif isinstance(P, DrawerParams):
        P.T_world_closed = P.T_world_closed.copy()
        P.T_world_closed[:3, 3] += shift
    scene.reset()
