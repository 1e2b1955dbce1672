"""Active constraints (geometric limits on the end-effector pose), one class per kind.

Each kind reads its parameters from a skill file (``from_yaml``), writes them back
(``to_yaml``), summarises itself and projects a flat pose onto itself in the tick
(``project``, moving the constrained frame minimally); :data:`CONSTRAINTS` finds a kind
by its ``type`` name. The checks run on Python floats, precomputed from the parameters
when the constraint is made; only a projection that turns the pose builds arrays.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .. import se3
from .modelfile import VectorFieldModel
from .reader import Reader
from .registry import ByValue, Registry, summarised
from .sketch import Cone, Cuboid, Dots, Plane, Shape, Sphere, direction_words
from .workspace import Workspace

Array = NDArray[np.float64]
Flat = se3.Flat
Vec3 = tuple[float, float, float]


def _floats3(a: Array) -> Vec3:
    x, y, z = a.tolist()
    return float(x), float(y), float(z)


def _set(obj: object, **values: Any) -> None:
    """Set the precomputed fields of a frozen dataclass (in ``__post_init__``)."""
    for k, v in values.items():
        object.__setattr__(obj, k, v)


@dataclass(frozen=True, kw_only=True, eq=False)
class ActiveConstraint(ByValue, ABC):
    """One active constraint of a state, on the pose of ``frame`` (on the end-effector)."""

    type: ClassVar[str]
    bounds: ClassVar[bool] = True
    """A limit the hand can be pushed against (a view says it holds the hand when its
    projection moves the pose); False for a kind that guides rather than bounds."""
    frame: str = "ee"

    @classmethod
    @abstractmethod
    def from_yaml(cls, r: Reader, cd: dict, path: str) -> ActiveConstraint:
        """Read and validate this kind's parameters from the mapping ``cd`` at ``path``."""

    @abstractmethod
    def to_yaml(self) -> dict[str, Any]:
        """The constraint as the plain dict :meth:`from_yaml` reads (an entry of a state's
        ``active_constraints`` list): every parameter, exactly."""

    def summary(self) -> dict[str, Any]:
        """The constraint as plain data (``sctd inspect --json``, the skill query)."""
        return summarised(self.to_yaml())

    def models(self) -> tuple[tuple[str, VectorFieldModel], ...]:
        """The model files this constraint reads, as (relative path, model)."""
        return ()

    def sketch(self, G: Flat) -> tuple[Shape, ...]:
        """What the constraint looks like (:mod:`sctd.skill.sketch`, object frame) with
        its ``frame`` at pose G: none for a kind with no shape."""
        return ()

    @abstractmethod
    def project(self, F: Flat, G: Flat, ws: Workspace) -> Flat:
        """Project the ee pose F (object frame) onto the constraint.

        Parameters
        ----------
        F : Flat
            The end-effector's pose.
        G : Flat
            The constrained frame's pose for this F.
        ws : Workspace

        Returns
        -------
        Flat
            F itself (the same object) when it satisfies the constraint, else the pose
            with the constrained frame moved minimally onto it.
        """


CONSTRAINTS: Registry[ActiveConstraint] = Registry("active constraint")


def _rotate_about(F: Flat, G: Flat, R: Array) -> Flat:
    """Rotate the pose F by R (3, 3; object axes) about the origin of frame pose G."""
    return se3.compose_flat(se3.flat_rotation_about(R.ravel().tolist(), *G[9:]), F)


TILT_CONE_LENGTH = 0.08  # m: how long a tilt cone is drawn
BAND_SIZE = 0.3  # m: the side of a band's bounds as drawn
MAX_TURN = math.pi / 2  # rad: a neighbour orientation turns a frame at most this far from its own


@CONSTRAINTS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class TiltCone(ActiveConstraint):
    """``axis`` (3,; in ``frame``) stays within ``max_angle`` of ``reference`` (3,; object
    frame); a tilted frame is turned back about its origin onto the cone."""

    type: ClassVar[str] = "tilt_cone"
    axis: Array
    reference: Array
    max_angle: float
    _axis3: Vec3 = field(init=False, repr=False, compare=False)
    _reference3: Vec3 = field(init=False, repr=False, compare=False)
    _cos_max: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _set(self, _axis3=_floats3(self.axis), _reference3=_floats3(self.reference),
             _cos_max=math.cos(self.max_angle))

    @classmethod
    def from_yaml(cls, r: Reader, cd: dict, path: str) -> TiltCone:
        r.known_keys(cd, path, {"type", "frame", "axis", "reference", "max_angle"})
        return cls(
            frame=r.ee_frame_ref(cd.get("frame", "ee"), f"{path}.frame"),
            axis=r.vector(cd.get("axis", [0, 0, 1]), f"{path}.axis", 3, unit=True),
            reference=r.vector(cd.get("reference", [0, 0, 1]), f"{path}.reference", 3, unit=True),
            max_angle=r.number(cd.get("max_angle"), f"{path}.max_angle", 0.0, math.pi),
        )

    def to_yaml(self) -> dict[str, Any]:
        return {"type": self.type, "frame": self.frame, "axis": self.axis.tolist(),
                "reference": self.reference.tolist(), "max_angle": self.max_angle}

    def project(self, F: Flat, G: Flat, ws: Workspace) -> Flat:
        ax, ay, az = self._axis3
        rx, ry, rz = self._reference3
        a0 = G[0] * ax + G[1] * ay + G[2] * az
        a1 = G[3] * ax + G[4] * ay + G[5] * az
        a2 = G[6] * ax + G[7] * ay + G[8] * az
        cos_a = a0 * rx + a1 * ry + a2 * rz
        if cos_a >= self._cos_max:
            return F
        a = np.array([a0, a1, a2])
        perp = a - cos_a * self.reference
        pn = float(np.linalg.norm(perp))
        if pn < 1e-9:  # exactly opposite: any boundary direction will do
            perp = np.cross(self.reference, [1.0, 0.0, 0.0])
            if np.linalg.norm(perp) < 1e-6:
                perp = np.cross(self.reference, [0.0, 1.0, 0.0])
            pn = float(np.linalg.norm(perp))
        boundary = math.cos(self.max_angle) * self.reference + math.sin(self.max_angle) * perp / pn
        return _rotate_about(F, G, se3.rotation_between(a, boundary))

    def sketch(self, G: Flat) -> tuple[Shape, ...]:
        """The cone the frame's axis stays in, at the frame's origin."""
        return (Cone(f"{self.frame} tilts at most {math.degrees(self.max_angle):.0f} deg",
                     np.asarray(G[9:]), self.reference, self.max_angle, TILT_CONE_LENGTH),)


@CONSTRAINTS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class Band(ActiveConstraint):
    """``frame``'s origin keeps a signed distance in [lower, upper] along the unit
    ``normal`` (3,) from the plane through ``point`` (3,) (object frame): a height band
    when normal is z."""

    type: ClassVar[str] = "band"
    normal: Array
    point: Array
    lower: float
    upper: float
    _normal3: Vec3 = field(init=False, repr=False, compare=False)
    _point3: Vec3 = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _set(self, _normal3=_floats3(self.normal), _point3=_floats3(self.point))

    @classmethod
    def from_yaml(cls, r: Reader, cd: dict, path: str) -> Band:
        r.known_keys(cd, path, {"type", "frame", "normal", "point", "lower", "upper"})
        lower = r.number(cd.get("lower"), f"{path}.lower")
        upper = r.number(cd.get("upper"), f"{path}.upper")
        if upper < lower:
            raise r.fail(f"{path}.upper", f"must be >= lower ({lower}), got {upper}")
        return cls(
            frame=r.ee_frame_ref(cd.get("frame", "ee"), f"{path}.frame"),
            normal=r.vector(cd.get("normal", [0, 0, 1]), f"{path}.normal", 3, unit=True),
            point=r.vector(cd.get("point", [0, 0, 0]), f"{path}.point", 3),
            lower=lower, upper=upper,
        )

    def to_yaml(self) -> dict[str, Any]:
        return {"type": self.type, "frame": self.frame, "normal": self.normal.tolist(),
                "point": self.point.tolist(), "lower": self.lower, "upper": self.upper}

    def project(self, F: Flat, G: Flat, ws: Workspace) -> Flat:
        nx, ny, nz = self._normal3
        cx, cy, cz = self._point3
        s = nx * (G[9] - cx) + ny * (G[10] - cy) + nz * (G[11] - cz)
        delta = (self.lower - s) if s < self.lower else (self.upper - s) if s > self.upper else 0.0
        if delta == 0.0:
            return F
        return se3.translate_flat(F, delta * nx, delta * ny, delta * nz)

    def sketch(self, G: Flat) -> tuple[Shape, ...]:
        """The band's two bounds, squares centred under and over the frame's origin."""
        p = np.asarray(G[9:], dtype=float)
        foot = p - float(self.normal @ (p - self.point)) * self.normal  # in the plane through point
        along = direction_words(self.normal)
        return tuple(Plane(f"{self.frame} {word} {d:g} m along {along}", foot + d * self.normal, self.normal,
                           BAND_SIZE)
                     for word, d in (("at least", self.lower), ("at most", self.upper)))


@CONSTRAINTS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class Box(ActiveConstraint):
    """``frame``'s origin stays inside the axis-aligned box [lower, upper] (3, each;
    object frame)."""

    type: ClassVar[str] = "box"
    lower: Array
    upper: Array
    _lower3: Vec3 = field(init=False, repr=False, compare=False)
    _upper3: Vec3 = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _set(self, _lower3=_floats3(self.lower), _upper3=_floats3(self.upper))

    @classmethod
    def from_yaml(cls, r: Reader, cd: dict, path: str) -> Box:
        r.known_keys(cd, path, {"type", "frame", "lower", "upper"})
        lower = r.vector(cd.get("lower"), f"{path}.lower", 3)
        upper = r.vector(cd.get("upper"), f"{path}.upper", 3)
        if np.any(upper < lower):
            raise r.fail(f"{path}.upper", "every upper bound must be >= its lower bound")
        return cls(frame=r.ee_frame_ref(cd.get("frame", "ee"), f"{path}.frame"), lower=lower, upper=upper)

    def to_yaml(self) -> dict[str, Any]:
        return {"type": self.type, "frame": self.frame, "lower": self.lower.tolist(),
                "upper": self.upper.tolist()}

    def project(self, F: Flat, G: Flat, ws: Workspace) -> Flat:
        p = G[9:]
        q = [min(max(x, lo), hi) for x, lo, hi in zip(p, self._lower3, self._upper3, strict=True)]
        if q[0] == p[0] and q[1] == p[1] and q[2] == p[2]:
            return F
        return (*F[:9], F[9] + q[0] - p[0], F[10] + q[1] - p[1], F[11] + q[2] - p[2])

    def sketch(self, G: Flat) -> tuple[Shape, ...]:
        return (Cuboid(f"{self.frame} stays in this box", self.lower, self.upper),)


def _rows_of_unit_quaternion(x: float, y: float, z: float, w: float) -> tuple[float, ...]:
    """The rotation matrix (row-major, 9 floats) of the unit quaternion (x, y, z, w)."""
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w),
            2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w),
            2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y))


def _yields(r: Reader, cd: dict, path: str) -> bool:
    """A neighbour orientation's ``yields_to_turn``: it names the turns about its
    ``pivot``, so it needs one."""
    yields = r.boolean(cd.get("yields_to_turn", False), f"{path}.yields_to_turn")
    if yields and cd.get("pivot") is None:
        raise r.fail(f"{path}.yields_to_turn", "needs a pivot (the point the hand turns about)")
    return yields


@CONSTRAINTS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class NeighbourOrientation(ActiveConstraint):
    """Orientation of ``frame`` pulled to the distance-weighted mean orientation of the
    demonstration points near it (Ch. 4.2.5, Algorithm 7 lines 2-5).

    ``pivot`` (3,): turn about this point of the frame (its offset), not its origin.
    ``rotation_weight`` (m per rad): > 0 picks the neighbours nearest in pose, not in
    position alone (the demonstrations near where the hand is *and* as it is turned).
    Within a command it turns at most ``ws.turn_budget``.

    ``yields_to_turn`` (with ``pivot``): where the push turns the hand about a point of
    its own (a rigid field's ``pivot``: the task's turn, ``ws.turn_axis``), the turns
    about that point are the person's: of its correction only the twist about the
    pivot's own axis (the frame's origin to the pivot) is kept. A pouring sphere tilts
    a bottle about its opening, and the demonstrations nearest a bottle being tilted
    back are those of the way in, tilted on further: the person's push back should tilt
    it back, not be undone by the pull to them, whichever way the push also leans
    sideways. (A turn about a far axis keeps the pull's whole say: a door's handle,
    turned about the hinge, is held as the demonstrators held it.)

    ``max_turn`` (rad): a frame turned further than this from the neighbours' mean
    orientation keeps its own. The hand was brought in turned another way (from another
    task's start, half a turn about the vertical), away from every demonstration; turning
    it back the shortest way, unasked, is a motion the person did not command and winds
    the wrist into its limit, where the arm then follows nothing (the skill's position
    guidance holds as before).
    """

    type: ClassVar[str] = "neighbour_orientation"
    bounds: ClassVar[bool] = False  # it turns the hand towards the demonstrations: guidance
    model_file: str
    model: VectorFieldModel
    max_n: int = 5
    max_d: float = 0.15
    pivot: Array | None = None
    rotation_weight: float = 0.0
    max_turn: float = MAX_TURN
    yields_to_turn: bool = False
    _pivot3: Vec3 | None = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _set(self, _pivot3=None if self.pivot is None else _floats3(self.pivot))

    @classmethod
    def from_yaml(cls, r: Reader, cd: dict, path: str) -> NeighbourOrientation:
        r.known_keys(cd, path, {"type", "model", "frame", "max_n", "max_d", "pivot", "rotation_weight",
                                "max_turn", "yields_to_turn"})
        model_file = r.string(cd.get("model"), f"{path}.model")
        return cls(
            model_file=model_file,
            model=r.model(model_file, f"{path}.model"),
            frame=r.ee_frame_ref(cd.get("frame", "ee"), f"{path}.frame"),
            max_n=r.integer(cd.get("max_n", 5), f"{path}.max_n", 1),
            max_d=r.number(cd.get("max_d", 0.15), f"{path}.max_d", 0.0, lo_open=True),
            pivot=None if cd.get("pivot") is None else r.vector(cd["pivot"], f"{path}.pivot", 3),
            rotation_weight=r.number(cd.get("rotation_weight", 0.0), f"{path}.rotation_weight", 0.0, 10.0),
            max_turn=r.number(cd.get("max_turn", MAX_TURN), f"{path}.max_turn", 0.0, math.pi, lo_open=True),
            yields_to_turn=_yields(r, cd, path),
        )

    def to_yaml(self) -> dict[str, Any]:
        out = {"type": self.type, "model": self.model_file, "frame": self.frame, "max_n": self.max_n,
               "max_d": self.max_d, "rotation_weight": self.rotation_weight}
        if self.pivot is not None:
            out["pivot"] = self.pivot.tolist()
        if self.max_turn != MAX_TURN:
            out["max_turn"] = self.max_turn
        if self.yields_to_turn:
            out["yields_to_turn"] = True
        return out

    def summary(self) -> dict[str, Any]:
        """:meth:`to_yaml` and how many demonstration points the model has."""
        return super().summary() | {"points": len(self.model.points)}

    def models(self) -> tuple[tuple[str, VectorFieldModel], ...]:
        return ((self.model_file, self.model),)

    def sketch(self, G: Flat) -> tuple[Shape, ...]:
        """The demonstration points whose orientations it takes."""
        return (Dots(f"{self.frame} turns as the demonstrations did here", self.model.points),)

    def _goal(self, G: Flat, q_G: tuple[float, float, float, float], ws: Workspace
              ) -> tuple[float, float, float, float] | None:
        """The neighbours' weighted mean orientation (x, y, z, w; not normalised) for the
        frame at pose G (orientation ``q_G``), or None when no demonstration point is
        near."""
        nb = ws.neighbours[self.model_file]
        if self.rotation_weight > 0.0:
            answer = nb.query_pose(G[9:], q_G, self.max_n, self.max_d, self.rotation_weight)
        else:
            answer = nb.query(G[9:], self.max_n, self.max_d)
        return nb.mean_orientation(answer)

    def project(self, F: Flat, G: Flat, ws: Workspace) -> Flat:
        if not ws.turn_budget > 0.0:  # no push: no turn, not even an identity's round-off
            return F
        q_G = se3.quaternion_from_flat(G)
        goal = self._goal(G, q_G, ws)
        if goal is None:
            return F
        gx, gy, gz, gw = goal
        # The correction q_goal * q_frame^-1 and its angle, on floats (this runs every
        # tick): turned towards the goal at most the budget.
        fx, fy, fz, fw = q_G
        cw = gw * fw + gx * fx + gy * fy + gz * fz
        cx = -gw * fx + gx * fw - gy * fz + gz * fy
        cy = -gw * fy + gy * fw - gz * fx + gx * fz
        cz = -gw * fz + gz * fw - gx * fy + gy * fx
        if cw < 0.0:
            cw, cx, cy, cz = -cw, -cx, -cy, -cz
        vn = math.sqrt(cx * cx + cy * cy + cz * cz)
        n = math.sqrt(cw * cw + vn * vn)
        if n < 1e-12:
            return F
        budget = ws.turn_budget
        angle = 2.0 * math.atan2(vn, cw)
        if angle > self.max_turn:
            return F  # turned another way than every demonstration near: keeps its own
        if self.yields_to_turn and ws.turn_axis is not None and self._pivot3 is not None and vn > 1e-15:
            # the push turns the hand about the pivot: the turns about it are the person's
            # (the demonstrations near a bottle tilted back are the way in's, tilted
            # further); only the twist about the pivot's own axis is corrected
            px, py, pz = self._pivot3
            qx, qy, qz = (G[0] * px + G[1] * py + G[2] * pz, G[3] * px + G[4] * py + G[5] * pz,
                          G[6] * px + G[7] * py + G[8] * pz)
            qn = math.sqrt(qx * qx + qy * qy + qz * qz)
            twist = (cx * qx + cy * qy + cz * qz) / (vn * qn)
            angle *= abs(twist)
            if angle < 1e-12:
                return F
            h = math.copysign(0.5 * min(angle, budget), twist)
            k = math.sin(h) / qn
            return self._turned(F, G, qx * k, qy * k, qz * k, math.cos(h))
        if vn > 1e-15 and angle > budget:
            h = 0.5 * budget
            k = math.sin(h) / vn
            cx, cy, cz, cw = cx * k, cy * k, cz * k, math.cos(h)
        else:
            cx, cy, cz, cw = cx / n, cy / n, cz / n, cw / n
        return self._turned(F, G, cx, cy, cz, cw)

    def _turned(self, F: Flat, G: Flat, cx: float, cy: float, cz: float, cw: float) -> Flat:
        """F turned by the unit quaternion (cx, cy, cz, cw), object frame, about the
        frame's origin at pose G or about its ``pivot``."""
        R9 = _rows_of_unit_quaternion(cx, cy, cz, cw)
        if self._pivot3 is None:
            return se3.compose_flat(se3.flat_rotation_about(R9, *G[9:]), F)
        px, py, pz = self._pivot3  # about a point of the hand (the opening of a bottle)
        o = (G[9] + G[0] * px + G[1] * py + G[2] * pz,
             G[10] + G[3] * px + G[4] * py + G[5] * pz,
             G[11] + G[6] * px + G[7] * py + G[8] * pz)
        return se3.compose_flat(se3.flat_rotation_about(R9, *o), F)


# -- limits on the step, not the pose ------------------------------------------------------
class StepLimit(ActiveConstraint, ABC):
    """An active constraint on how far the pose moves in one command, not on where it
    is: every pose satisfies it (:meth:`project` leaves it), and the engine bounds each
    command's step with :meth:`limit` after the state's other constraints, wherever it
    stands in the list."""

    def project(self, F: Flat, G: Flat, ws: Workspace) -> Flat:
        return F

    @abstractmethod
    def limit(self, F_prev: Flat, F_new: Flat, ws: Workspace, dt: float) -> Flat:
        """The step F_prev -> F_new (ee poses, object frame) bounded for a command of
        ``dt`` s: F_new itself when it is within the bound, else a pose on the way to
        it (:func:`~sctd.se3.interpolate_flat`)."""


@CONSTRAINTS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class SpeedNear(StepLimit):
    """Slow near the object: when ``point`` (3,; an offset in ``frame``, default its
    origin) comes within ``within`` m of the object's origin anywhere along a command's
    step (the segment between its ends, widened by how far a turn may take the point off
    it: a step that would leap across the zone is capped too), the step moves that point
    at most ``max_linear_speed`` (m/s) and turns the hand at most ``max_angular_speed``
    (rad/s) over the command's ``dt``, whatever the input and the other elements ask
    for.

    The step is scaled back along :func:`~sctd.se3.interpolate_flat`, on which the point's displacement after
    a fraction ``s`` of a step that turns by ``theta`` is at most ``s d + theta^2 r / 4``
    (``d`` the whole step's displacement, ``r`` the point's distance from the ee's
    origin: the chord of the turn against its share of the whole) and at most ``s (|t| +
    theta r)`` (``t`` the ee origin's displacement); the fraction is the largest that
    keeps either bound within the cap, so that any smaller one does too (the daemon's
    own step bound scales steps further along the same path).
    """

    type: ClassVar[str] = "speed_near"
    within: float
    max_linear_speed: float
    max_angular_speed: float
    point: Array | None = None
    _point3: Vec3 = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _set(self, _point3=(0.0, 0.0, 0.0) if self.point is None else _floats3(self.point))

    @classmethod
    def from_yaml(cls, r: Reader, cd: dict, path: str) -> SpeedNear:
        r.known_keys(cd, path, {"type", "frame", "within", "max_linear_speed", "max_angular_speed", "point"})
        return cls(
            frame=r.ee_frame_ref(cd.get("frame", "ee"), f"{path}.frame"),
            within=r.number(cd.get("within"), f"{path}.within", 0.0, 2.0, lo_open=True),
            max_linear_speed=r.number(cd.get("max_linear_speed"), f"{path}.max_linear_speed", 0.0, 1.0,
                                      lo_open=True),
            max_angular_speed=r.number(cd.get("max_angular_speed"), f"{path}.max_angular_speed", 0.0, 3.0,
                                       lo_open=True),
            point=None if cd.get("point") is None else _offset(r, cd["point"], f"{path}.point"),
        )

    def to_yaml(self) -> dict[str, Any]:
        out = {"type": self.type, "frame": self.frame, "within": self.within,
               "max_linear_speed": self.max_linear_speed, "max_angular_speed": self.max_angular_speed}
        if self.point is not None:
            out["point"] = self.point.tolist()
        return out

    def sketch(self, G: Flat) -> tuple[Shape, ...]:
        """The zone about the object's origin where the cap holds."""
        return (Sphere(f"at most {self.max_linear_speed:g} m/s, {self.max_angular_speed:g} rad/s within "
                       f"{self.within:g} m", np.zeros(3), self.within),)

    def _point(self, G: Flat) -> Vec3:
        px, py, pz = self._point3
        return (G[9] + G[0] * px + G[1] * py + G[2] * pz, G[10] + G[3] * px + G[4] * py + G[5] * pz,
                G[11] + G[6] * px + G[7] * py + G[8] * pz)

    def limit(self, F_prev: Flat, F_new: Flat, ws: Workspace, dt: float) -> Flat:
        if F_new is F_prev:
            return F_new
        ax, ay, az = self._point(ws.frame_pose(F_prev, self.frame))
        bx, by, bz = self._point(ws.frame_pose(F_new, self.frame))
        q = se3.relative_quaternion_flat(F_prev, F_new)
        theta = 2.0 * math.atan2(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]), q[3])
        r = math.sqrt((ax - F_prev[9]) ** 2 + (ay - F_prev[10]) ** 2 + (az - F_prev[11]) ** 2)
        chord = 0.25 * theta * theta * r  # how far the point's path may leave the segment a-b
        if _nearest(ax, ay, az, bx, by, bz) > self.within + chord:
            return F_new  # far from the object all along the step
        lin, ang = self.max_linear_speed * dt, self.max_angular_speed * dt
        d = math.sqrt((bx - ax) ** 2 + (by - ay) ** 2 + (bz - az) ** 2)
        move = math.sqrt((F_new[9] - F_prev[9]) ** 2 + (F_new[10] - F_prev[10]) ** 2
                         + (F_new[11] - F_prev[11]) ** 2)
        s = ang / theta if theta > ang else 1.0
        if not d + chord <= lin:
            reach = move + theta * r
            s_lin = lin / reach if reach > 0.0 else 0.0
            if lin > chord and d > 0.0:
                s_lin = max(s_lin, (lin - chord) / d)
            s = min(s, s_lin)
        if s >= 1.0:
            return F_new
        if not s > 0.0:  # (nothing may move: dt 0; NaN fails closed)
            return F_prev
        return se3.interpolate_flat(F_prev, F_new, s, q)


def _nearest(ax: float, ay: float, az: float, bx: float, by: float, bz: float) -> float:
    """The distance from the origin of the segment from a to b."""
    ex, ey, ez = bx - ax, by - ay, bz - az
    e2 = ex * ex + ey * ey + ez * ez
    t = 0.0 if e2 <= 0.0 else min(1.0, max(0.0, -(ax * ex + ay * ey + az * ez) / e2))
    return math.sqrt((ax + t * ex) ** 2 + (ay + t * ey) ** 2 + (az + t * ez) ** 2)


def _offset(r: Reader, v: Any, path: str) -> Array:
    """A point of the hand as an offset in a frame: 3 numbers, at most 1 m from it."""
    p = r.vector(v, path, 3)
    if float(np.linalg.norm(p)) > 1.0:
        raise r.fail(path, f"must be within 1 m of the frame's origin, got {float(np.linalg.norm(p)):.3f} m")
    return p
