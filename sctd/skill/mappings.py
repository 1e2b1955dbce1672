"""Input mappings (user input -> end-effector motion), one class per kind.

Each kind reads its parameters from a skill file (``from_yaml``), writes them back
(``to_yaml``), summarises and describes itself and applies itself to a flat pose in the
tick (``apply``); :data:`MAPPINGS` finds a kind by its ``type`` name. Displacements
follow the convention of :mod:`sctd.se3`.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from .. import se3
from .constraints import MAX_TURN
from .errors import SkillError
from .fields import Field, sigmoid
from .modelfile import VectorFieldModel
from .reader import Reader, kind_of
from .registry import ByValue, Registry, plain, summarised
from .workspace import Workspace

Array = NDArray[np.float64]
Flat = se3.Flat
Vec3 = tuple[float, float, float]
# m: a pivot nearer the frame's origin gives no axis to turn a command with
PIVOT_OFF = 0.01

AXIS_NAMES = ("tx", "ty", "tz", "rx", "ry", "rz")  # a displacement's rows, a linear matrix's too
MATRIX_WIDTHS = (1, 2, 3, 6)  # input columns a linear ``matrix`` may have (``axes``: 1 to 6)
INTENT_PRIOR = 0.1  # share of the fields' weights mixed into P(F | p) before the command's evidence


@dataclass(frozen=True, kw_only=True, eq=False)
class InputMapping(ByValue, ABC):
    """One input mapping of a state: moves the end-effector for the user's input.

    ``frame`` is the feature frame the motion is expressed relative to.
    """

    type: ClassVar[str]
    frame: str = "ee"

    @classmethod
    @abstractmethod
    def from_yaml(cls, r: Reader, md: dict, path: str) -> InputMapping:
        """Read and validate this kind's parameters from the mapping ``md`` at ``path``."""

    @abstractmethod
    def to_yaml(self) -> dict[str, Any]:
        """The mapping as the plain dict :meth:`from_yaml` reads (an entry of a state's
        ``input_mapping`` list): every parameter, exactly."""

    def summary(self) -> dict[str, Any]:
        """The mapping as plain data (``sctd inspect --json``, the skill query)."""
        return summarised(self.to_yaml())

    def describe(self) -> str:
        """What the mapping does, in a line for a person (``sctd inspect``)."""
        return str({k: v for k, v in self.summary().items() if k not in ("type", "frame")})

    @abstractmethod
    def input_axes(self) -> set[int]:
        """The indices of the input axes this mapping reads."""

    def models(self) -> tuple[tuple[str, VectorFieldModel], ...]:
        """The model files this mapping reads, as (relative path, model)."""
        return ()

    @abstractmethod
    def apply(self, F: Flat, u: Sequence[float], dt: float, ws: Workspace) -> Flat:
        """The ee pose F (object frame) moved by input ``u`` over ``dt`` seconds.

        ``u`` holds values in [-1, 1]; axes beyond what the mapping reads are ignored,
        missing ones count as zero.
        """


MAPPINGS: Registry[InputMapping] = Registry("input mapping")


def _matrix(r: Reader, v: Any, path: str) -> Array:
    """A (6, k) selection matrix given row by row (rows tx, ty, tz, rx, ry, rz)."""
    if not isinstance(v, list) or len(v) != 6:
        raise r.fail(path, f"expected 6 rows (tx, ty, tz, rx, ry, rz), got {kind_of(v)}")
    rows = []
    width = None
    for i, row in enumerate(v):
        if not isinstance(row, list) or not row:
            raise r.fail(f"{path}[{i}]", f"expected a list of numbers, got {kind_of(row)}")
        if width is None:
            width = len(row)
        elif len(row) != width:
            raise r.fail(f"{path}[{i}]", f"expected {width} columns like row 0, got {len(row)}")
        rows.append([r.number(x, f"{path}[{i}][{j}]") for j, x in enumerate(row)])
    if width not in MATRIX_WIDTHS:
        raise r.fail(path, f"expected 1, 2, 3 or 6 input columns, got {width}")
    m = np.array(rows)
    if not np.any(m):
        raise r.fail(path, "all-zero matrix maps every input to nothing")
    return m


def _axes(r: Reader, v: Any, path: str) -> Array:
    """The (6, k) selection matrix of a list of k axis names (``-`` negates, null skips)."""
    if not isinstance(v, list) or not 1 <= len(v) <= 6:
        raise r.fail(path, f"expected a list of 1-6 axis names, got {kind_of(v)}")
    m = np.zeros((6, len(v)))
    for j, a in enumerate(v):
        if a is None:
            continue
        sign = 1.0
        if isinstance(a, str) and a.startswith("-"):
            sign, a = -1.0, a[1:]
        if a not in AXIS_NAMES:
            raise r.fail(f"{path}[{j}]", f"expected one of {', '.join(AXIS_NAMES)} "
                         f"(optionally with '-') or null, got {a!r}")
        m[AXIS_NAMES.index(a), j] = sign
    if not np.any(m):
        raise r.fail(path, "no axis selected")
    return m


def _axis_names(m: Array) -> list[str | None]:
    """The ``axes`` list of a selection matrix (6, k): per column the axis it drives,
    ``-`` when negated, None when it drives none."""
    names: list[str | None] = []
    for j in range(m.shape[1]):
        rows = np.flatnonzero(m[:, j])
        names.append(None if not len(rows) else ("-" if m[rows[0], j] < 0 else "") + AXIS_NAMES[rows[0]])
    return names


@MAPPINGS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class LinearMapping(InputMapping):
    """Linear input mapping (eq. 4.1, Algorithm 2).

    ``matrix`` (6, k) maps input axes to a displacement [tx, ty, tz, rx, ry, rz] at full
    speed: rotation about ``frame``'s origin and its own axes (``rotation == "frame"``,
    Algorithm 2) or the object's axes; translation in the object's axes
    (``translation == "object"``, Algorithm 2) or in ``frame``'s axes.
    """

    type: ClassVar[str] = "linear"
    matrix: Array
    translation: Literal["object", "frame"] = "object"
    rotation: Literal["frame", "object"] = "frame"
    # the matrix's non-zero entries per row, (column, value): the tick reads only these
    _entries: tuple[tuple[tuple[int, float], ...], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        m = self.matrix
        object.__setattr__(self, "_entries", tuple(
            tuple((j, float(m[i, j])) for j in range(m.shape[1]) if m[i, j] != 0.0) for i in range(6)))

    @classmethod
    def from_yaml(cls, r: Reader, md: dict, path: str) -> LinearMapping:
        r.known_keys(md, path, {"type", "frame", "matrix", "axes", "translation", "rotation"})
        frame = r.frame_ref(md.get("frame", "ee"), f"{path}.frame")
        if "matrix" in md and "axes" in md:
            raise r.fail(path, "give either matrix or axes, not both")
        if "matrix" in md:
            matrix = _matrix(r, md["matrix"], f"{path}.matrix")
        elif "axes" in md:
            matrix = _axes(r, md["axes"], f"{path}.axes")
        else:
            raise r.fail(path, "a linear mapping needs matrix (6 rows) or axes")
        translation = r.choice(md.get("translation", "object"), f"{path}.translation", ("object", "frame"))
        rotation = r.choice(md.get("rotation", "frame"), f"{path}.rotation", ("frame", "object"))
        return cls(frame=frame, matrix=matrix, translation=translation,  # type: ignore[arg-type]
                   rotation=rotation)  # type: ignore[arg-type]

    def to_yaml(self) -> dict[str, Any]:
        """The ``matrix``; a matrix of 4 or 5 columns, which only ``axes`` can give, as its
        ``axes``."""
        m = self.matrix
        shape = {"matrix": m.tolist()} if m.shape[1] in MATRIX_WIDTHS else {"axes": _axis_names(m)}
        return {"type": self.type, "frame": self.frame, **shape, "translation": self.translation,
                "rotation": self.rotation}

    def summary(self) -> dict[str, Any]:
        """:meth:`to_yaml` with the ``matrix`` whatever its width."""
        doc = {k: v for k, v in self.to_yaml().items() if k != "axes"}
        return summarised(doc | {"matrix": self.matrix.tolist()})

    def describe(self) -> str:
        """Each input column and the axes it drives: ``u0->+1tx, u1->+1ty-0.5tz`` (from
        the matrix as the summary shows it)."""
        m = plain(self.matrix)
        cols = []
        for j in range(len(m[0])):
            terms = [f"{m[i][j]:+g}{AXIS_NAMES[i]}" for i in range(6) if m[i][j] != 0]
            cols.append(f"u{j}->" + ("".join(terms) if terms else "none"))
        return ", ".join(cols)

    def input_axes(self) -> set[int]:
        """The matrix's non-zero columns."""
        return {j for j in range(self.matrix.shape[1]) if np.any(self.matrix[:, j] != 0.0)}

    def apply(self, F: Flat, u: Sequence[float], dt: float, ws: Workspace) -> Flat:
        """Algorithm 2 on floats: rotate about the frame's origin and axes
        (``T_f Rot(r) T_f^-1 T``), then translate (in the object's axes, or the frame's
        before the rotation)."""
        n = len(u)
        speeds = ws.speeds
        d = [0.0] * 6
        for i, row in enumerate(self._entries):
            for j, coeff in row:
                if j < n:
                    d[i] += coeff * speeds[i] * u[j]
        dx, dy, dz, rx, ry, rz = d[0] * dt, d[1] * dt, d[2] * dt, d[3] * dt, d[4] * dt, d[5] * dt
        fixed = ws.fixed.get(self.frame)
        frame = fixed[0] if fixed is not None else ws.offsets[self.frame].frame(F)
        out = F
        if rx or ry or rz:
            out = self._rotate(F, frame, se3.flat_from_rotvec(rx, ry, rz), fixed, ws)
        if self.translation == "frame":
            dx, dy, dz = (frame[0] * dx + frame[1] * dy + frame[2] * dz,
                          frame[3] * dx + frame[4] * dy + frame[5] * dz,
                          frame[6] * dx + frame[7] * dy + frame[8] * dz)
        return (*out[:9], out[9] + dx, out[10] + dy, out[11] + dz)

    def _rotate(self, F: Flat, frame: Flat, rot: Flat, fixed: tuple[Flat, Flat] | None,
                ws: Workspace) -> Flat:
        """F turned by ``rot`` about the frame's origin (pose ``frame``)."""
        if self.rotation == "object":  # about the frame's origin, around the object's axes
            return se3.compose_flat(se3.flat_rotation_about(rot, *frame[9:]), F)
        if fixed is not None:  # T_f Rot T_f^-1 T, T_f fixed in the object
            return se3.compose_flat(se3.compose_flat(se3.compose_flat(frame, rot), fixed[1]), F)
        off = ws.offsets[self.frame]
        if off.R is None:  # T [Rot about t]
            return se3.compose_flat(F, se3.flat_rotation_about(rot, *off.t))
        T_e = off.flat  # T T_e Rot T_e^-1
        return se3.compose_flat(F, se3.compose_flat(se3.compose_flat(T_e, rot), se3.invert_flat(T_e)))


def intent_membership(P: Sequence[float], prior: Sequence[float], s: Sequence[float],
                      kappa: float) -> Array:
    """``P(F | p, u)``: the position's membership ``P`` (K,) (mixed with ``INTENT_PRIOR``
    of the fields' weights ``prior`` (K,), so that no field is ruled out by position
    alone) times each field's agreement with the command, ``exp(kappa * s_F)``,
    normalised. (On floats, with the numbers of the same sum on arrays.)"""
    post = [((1.0 - INTENT_PRIOR) * p + INTENT_PRIOR * q) * math.exp(kappa * (x - 1.0))
            for p, q, x in zip(P, prior, s, strict=True)]
    # numpy sums fewer than 8 numbers in order, more pairwise: the same total either way
    total = sum(post) if len(post) < 8 else float(np.sum(post))
    return np.array([x / total for x in post]) if total > 1e-300 else np.array(P, dtype=float)


def _rodrigues(x: float, y: float, z: float) -> tuple[float, ...]:
    """The rotation matrix (row-major, 9 floats) of the rotation vector (x, y, z)
    (Rodrigues)."""
    th = math.sqrt(x * x + y * y + z * z)
    if th < 1e-12:
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    kx, ky, kz = x / th, y / th, z / th
    c, s = math.cos(th), math.sin(th)
    v = 1.0 - c
    return (c + kx * kx * v, kx * ky * v - kz * s, kx * kz * v + ky * s,
            ky * kx * v + kz * s, c + ky * ky * v, ky * kz * v - kx * s,
            kz * kx * v - ky * s, kz * ky * v + kx * s, c + kz * kz * v)


def _product3(A: Sequence[float], B: Sequence[float]) -> tuple[float, ...]:
    """``A @ B`` of two rotation matrices (row-major, their first nine entries)."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A[:9]
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = B[:9]
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
            a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8)


def turned_command(G: Flat, axis: Vec3, frm: Vec3, u: Vec3) -> Vec3:
    """The command ``u`` (object frame) turned by the shortest turn that takes the
    direction ``frm`` (unit, object frame) to where the frame's ``axis`` (unit, in the
    frame at pose ``G``) points now: ``u cos + (v x u) + v (v . u) / (1 + cos)``, with
    ``v = frm x a`` (Rodrigues' formula for that turn). Unturned where the axis points
    the opposite way (no shortest turn). On floats (the tick)."""
    k0, k1, k2 = axis
    a0 = G[0] * k0 + G[1] * k1 + G[2] * k2
    a1 = G[3] * k0 + G[4] * k1 + G[5] * k2
    a2 = G[6] * k0 + G[7] * k1 + G[8] * k2
    f0, f1, f2 = frm
    c = f0 * a0 + f1 * a1 + f2 * a2
    if c <= -1.0 + 1e-9:
        return u
    v0, v1, v2 = f1 * a2 - f2 * a1, f2 * a0 - f0 * a2, f0 * a1 - f1 * a0
    x, y, z = u
    w0, w1, w2 = v1 * z - v2 * y, v2 * x - v0 * z, v0 * y - v1 * x
    k = (v0 * x + v1 * y + v2 * z) / (1.0 + c)
    return c * x + w0 + k * v0, c * y + w1 + k * v1, c * z + w2 + k * v2


def rigid_step(F: Flat, G: Flat, d: Vec3, P: Sequence[float], fields: Sequence[Field],
               scale: float = 1.0, scale_of: Callable[[Vec3], float] | None = None,
               wound: Vec3 | None = None, arrive: float = 0.0) -> Flat:
    """Move the hand F (object frame) by the command ``d`` (3 floats: the displacement of
    the frame at pose ``G`` at the command's own speed), each field's share of it
    weighted by its membership ``P`` (K,).

    The share of a rotational field (:meth:`~sctd.skill.fields.Field.rigid_part`) is
    split into its part along the field, which turns the whole hand about the field's
    centre (sphere) or axis (cylinder), and its part across the field (off the sphere,
    away from the axis), a translation; ``scale_of`` gives each part's scaling by its
    own agreement with the fields (eq. 4.34 applied to the parts, not to the whole
    push). So a push half along a pouring sphere tilts the bottle at half the speed, not
    at the sigmoid of the whole push's agreement, and its other half does not carry the
    bottle's opening off the point it turns about faster than ``min_v``. Where the
    field's pivot is not brought to it (``reach`` < 1) the rest of the share, and every
    other field's share, is a translation at ``scale`` (the whole push's scaling).
    Without ``scale_of`` (``scale_by: whole``, or ``blend`` mode: ``d`` already scaled or
    bent, ``scale`` 1) the share's part along the field turns the hand and the rest
    translates it. On floats (the tick).

    ``wound``: the hand is turned far from every demonstration near (not None): a field
    without a ``pivot`` (a door's hinge, 30 cm off) moves it along the arc unturned, one
    with (a bottle's opening) still turns it (:meth:`VectorFieldMapping._turned_away`)."""
    R_hand: Sequence[float] = F  # the hand's rotation, row-major (its first nine entries)
    x, y, z = F[9], F[10], F[11]
    rx, ry, rz = d[0] * scale, d[1] * scale, d[2] * scale  # the translation: every share at the scale
    for k, f in enumerate(fields):
        pk = P[k]
        if pk < 1e-6:
            continue
        s0, s1, s2 = pk * d[0], pk * d[1], pk * d[2]
        if arrive > 0.0:
            s0, s1, s2 = _turning_share(f, G, (s0, s1, s2), arrive)
        part = f.rigid_part(G, (s0, s1, s2))
        if part is None or not part.reach:
            continue
        t, w, (c0, c1, c2), reach = part
        n0, n1, n2 = s0 - t[0], s1 - t[1], s2 - t[2]  # the share's part across the field
        along, across = (1.0, 1.0) if scale_of is None else (scale_of(t), scale_of((n0, n1, n2)))
        a = reach * across + (1.0 - reach) * scale
        b = (1.0 - reach) * scale  # the part along the field that does not turn the hand
        rx += a * n0 + b * t[0] - scale * s0
        ry += a * n1 + b * t[1] - scale * s1
        rz += a * n2 + b * t[2] - scale * s2
        g = reach * along
        if not (t[0] or t[1] or t[2]) or not g:
            continue
        if wound is not None and f.pivot is None:
            rx, ry, rz = rx + g * t[0], ry + g * t[1], rz + g * t[2]  # along the arc, unturned
            continue
        R = _rodrigues(w[0] * g, w[1] * g, w[2] * g)
        R_hand = _product3(R, R_hand)
        a0, a1, a2 = x - c0, y - c1, z - c2
        x = R[0] * a0 + R[1] * a1 + R[2] * a2 + c0
        y = R[3] * a0 + R[4] * a1 + R[5] * a2 + c1
        z = R[6] * a0 + R[7] * a1 + R[8] * a2 + c2
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = R_hand[:9]
    return (r0, r1, r2, r3, r4, r5, r6, r7, r8, x + rx, y + ry, z + rz)


def _turning_share(f: Field, G: Flat, s: Vec3, arrive: float) -> Vec3:
    """The share ``s`` of field ``f`` less its part that carries the field's pivot towards
    where it turns about (:meth:`~sctd.skill.fields.Field.to_centre`): all of that part
    from ``arrive`` (m) off, none at the centre. What is taken out stays a translation
    (:func:`rigid_step`): a cup brought to the lips comes on upright, and turns about
    its rim once the rim is there."""
    v = f.to_centre(G)
    if v is None:
        return s
    dist = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    a = (s[0] * v[0] + s[1] * v[1] + s[2] * v[2]) / dist if dist > 1e-9 else 0.0
    if a <= 0.0:
        return s
    k = min(1.0, dist / arrive) * a / dist
    return s[0] - k * v[0], s[1] - k * v[1], s[2] - k * v[2]


@MAPPINGS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class VectorFieldMapping(InputMapping):
    """Vector-field input mapping (Ch. 4.2.5, Algorithm 7).

    The first three input axes are a translation command in the object's axes. In
    ``scale`` mode the command is scaled by the sigmoid-normalised agreement with the
    fields (eqs. 4.31-4.34); in ``blend`` mode its direction is bent towards them
    (eq. 4.35) without changing its magnitude, so zero input never moves.

    ``motion``: ``translate`` moves the frame by the (scaled or bent) command, as in the
    thesis; ``rigid`` turns the part of it that follows a rotational field (tangent to
    a sphere, around a cylinder's axis), weighted by the field's membership, into a
    rotation of the whole hand about the field's centre or axis, so that the hand turns
    as it moves along the field (a bottle tilts about its opening, a crank's handle
    keeps its grip) instead of waiting for an orientation constraint to catch up.

    ``combine``: how the fields' agreements make one scaling (``scale``) and one bend
    (``blend``): ``most_probable`` (eq. 4.31) and ``weighted`` (eq. 4.32) weigh them by
    the position's membership ``P(F | p)``; ``intent`` by the membership given the
    command as well, ``P(F | p, u) ~ P'(F | p) exp(intent_kappa * s_F(u))`` with ``P'``
    the membership mixed with 10 % of the fields' weights: where fields overlap in
    space (the start of a reach and the end of a pull), the one the user's push
    follows is the one the user means.

    ``direction``: ``forward`` (the thesis) takes a field's direction as the only way
    along it, so a push back along the demonstrated path agrees least (``s = -1``) and is
    scaled down to ``min_v``; ``both`` takes the field's line both ways (``|s|``, and in
    ``blend`` the bend towards whichever way the push goes): the hand goes back the way
    it came (out of a drawer, off a person's lips) as fast as it came.

    ``scale_by`` (``scale`` mode with ``rigid`` motion): ``whole`` (the thesis, eq. 4.34)
    scales the whole push by its agreement; ``parts`` splits a rotational field's share
    of it into the part along the field and the part across it and scales each by its
    own agreement (:func:`rigid_step`): the push along a pouring sphere turns the bottle
    at the push's speed, its part off the sphere moves the opening at ``min_v``. Learned
    for a state of its own field (``sctd learn --vf-states auto``), where the part across
    the field is off every field of the state.

    ``command_turns_from`` (``rigid`` motion, one field with a ``pivot`` off the frame's
    origin): a unit direction in the object frame, where the axis from the frame to that
    pivot pointed when the stick's axes were the object's (the learner writes the
    demonstrations' direction where they entered the state). The stick's axes turn with
    that axis, by the shortest turn from this direction to where the axis points now
    (:func:`turned_command`): as a bottle tilts about its opening, the push that tilted
    it keeps tilting it and the opposite push brings it back, at any tilt; read in the
    object's axes, the push along a pouring sphere turns by the tilt itself (at 90
    degrees, the push that tilted now moves the opening off the sphere at ``min_v``).
    """

    type: ClassVar[str] = "vector_field"
    model_file: str
    model: VectorFieldModel
    mode: Literal["scale", "blend"] = "scale"
    combine: Literal["most_probable", "weighted", "intent"] = "weighted"
    intent_kappa: float = 4.0
    min_v: float = 0.1
    k_s: float = 0.5
    max_n: int = 5
    max_d: float = 0.15
    blend: float = 0.5
    motion: Literal["translate", "rigid"] = "translate"
    direction: Literal["forward", "both"] = "forward"
    scale_by: Literal["whole", "parts"] = "whole"
    command_turns_from: Vec3 | None = None
    arrive: float = 0.0
    _pivot_axis: Vec3 = field(init=False, repr=False, default=(0.0, 0.0, 1.0))
    _pivoted: bool = field(init=False, repr=False, default=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_pivoted", any(f.pivot is not None for f in self.model.fields))
        if self.arrive and self.motion != "rigid":
            raise ValueError(f"arrive needs motion: rigid (it splits a turn), got motion: {self.motion}")
        if self.command_turns_from is None:
            return
        pivots = [f.pivot for f in self.model.fields if f.pivot is not None]
        if self.motion != "rigid" or len(pivots) != 1 or float(np.linalg.norm(pivots[0])) < PIVOT_OFF:
            raise ValueError("command_turns_from needs motion: rigid and exactly one field with a pivot "
                             f"{PIVOT_OFF * 1000:.0f} mm or more off the frame's origin; the model has "
                             f"{len(pivots)} field(s) with a pivot")
        a = pivots[0] / float(np.linalg.norm(pivots[0]))
        object.__setattr__(self, "_pivot_axis", (float(a[0]), float(a[1]), float(a[2])))
        f = np.array(self.command_turns_from, dtype=float)
        if f.shape != (3,) or not np.all(np.isfinite(f)) or float(np.linalg.norm(f)) < 1e-9:
            raise ValueError(f"command_turns_from must be a direction of 3 finite numbers, got "
                             f"{self.command_turns_from!r}")
        f = f / float(np.linalg.norm(f))
        object.__setattr__(self, "command_turns_from", (float(f[0]), float(f[1]), float(f[2])))

    @classmethod
    def from_yaml(cls, r: Reader, md: dict, path: str) -> VectorFieldMapping:
        r.known_keys(md, path, {"type", "model", "frame", "mode", "combine", "min_v", "k_s", "max_n",
                                "max_d", "blend", "motion", "intent_kappa", "direction", "scale_by",
                                "command_turns_from", "arrive"})
        model_file = r.string(md.get("model"), f"{path}.model")
        turns = None if md.get("command_turns_from") is None else \
            tuple(r.vector(md["command_turns_from"], f"{path}.command_turns_from", 3, unit=True).tolist())
        try:
            return cls._read(r, md, path, model_file, turns)
        except ValueError as e:
            if isinstance(e, SkillError):
                raise
            raise r.fail(f"{path}.arrive" if str(e).startswith("arrive") else f"{path}.command_turns_from",
                         str(e)) from None

    @classmethod
    def _read(cls, r: Reader, md: dict, path: str, model_file: str, turns: Any) -> VectorFieldMapping:
        """The mapping's parameters read from ``md`` (:meth:`from_yaml`)."""
        return cls(
            model_file=model_file,
            model=r.model(model_file, f"{path}.model"),
            frame=r.ee_frame_ref(md.get("frame", "ee"), f"{path}.frame"),
            mode=r.choice(md.get("mode", "scale"), f"{path}.mode", ("scale", "blend")),  # type: ignore[arg-type]
            combine=r.choice(md.get("combine", "weighted"), f"{path}.combine",  # type: ignore[arg-type]
                             ("most_probable", "weighted", "intent")),
            intent_kappa=r.number(md.get("intent_kappa", 4.0), f"{path}.intent_kappa", 0.0, 50.0),
            min_v=r.number(md.get("min_v", 0.1), f"{path}.min_v", 0.0, 1.0),
            k_s=r.number(md.get("k_s", 0.5), f"{path}.k_s", -0.99, 0.99),
            max_n=r.integer(md.get("max_n", 5), f"{path}.max_n", 1),
            max_d=r.number(md.get("max_d", 0.15), f"{path}.max_d", 0.0, lo_open=True),
            blend=r.number(md.get("blend", 0.5), f"{path}.blend", 0.0, 10.0),
            motion=r.choice(md.get("motion", "translate"), f"{path}.motion",  # type: ignore[arg-type]
                            ("translate", "rigid")),
            direction=r.choice(md.get("direction", "forward"), f"{path}.direction",  # type: ignore[arg-type]
                               ("forward", "both")),
            scale_by=r.choice(md.get("scale_by", "whole"), f"{path}.scale_by",  # type: ignore[arg-type]
                              ("whole", "parts")),
            command_turns_from=turns,
            arrive=r.number(md.get("arrive", 0.0), f"{path}.arrive", 0.0, 1.0),
        )

    def to_yaml(self) -> dict[str, Any]:
        """Every parameter; ``scale_by`` only where it is not ``whole`` (what a file
        without it reads), so that the text of a skill scaled as a whole stays as it was."""
        out = {"type": self.type, "model": self.model_file, "frame": self.frame, "mode": self.mode,
               "combine": self.combine, "intent_kappa": self.intent_kappa, "min_v": self.min_v,
               "k_s": self.k_s, "max_n": self.max_n, "max_d": self.max_d, "blend": self.blend,
               "motion": self.motion, "direction": self.direction}
        if self.scale_by != "whole":
            out["scale_by"] = self.scale_by
        if self.command_turns_from is not None:
            out["command_turns_from"] = [round(c, 6) for c in self.command_turns_from]
        if self.arrive:
            out["arrive"] = self.arrive
        return out

    def summary(self) -> dict[str, Any]:
        """:meth:`to_yaml` and how many fields the model has."""
        return super().summary() | {"fields": len(self.model.fields)}

    def describe(self) -> str:
        return f"{len(self.model.fields)} fields, mode {self.mode}"

    def input_axes(self) -> set[int]:
        """The first three: a translation command."""
        return {0, 1, 2}

    def models(self) -> tuple[tuple[str, VectorFieldModel], ...]:
        return ((self.model_file, self.model),)

    def apply(self, F: Flat, u: Sequence[float], dt: float, ws: Workspace) -> Flat:
        """Algorithm 7's translation part: scale (eqs. 4.31-4.34) or blend (eq. 4.35).
        Sets ``ws.scale`` and ``ws.membership``. (On floats: the numbers of the same
        arithmetic on 3-vectors, where numpy's per-call cost dominated the tick.)"""
        n = min(3, len(u))
        u0, u1, u2 = (float(u[j]) if j < n else 0.0 for j in range(3))
        mag = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        if mag < 1e-9:
            ws.scale = 0.0
            return F
        if mag > 1.0:
            u0, u1, u2 = u0 / mag, u1 / mag, u2 / mag
            mag = 1.0
        G = ws.frame_pose(F, self.frame)
        if self.command_turns_from is not None:
            u0, u1, u2 = turned_command(G, self._pivot_axis, self.command_turns_from, (u0, u1, u2))
        P, (s0, s1, s2), ws.scale = self._step(ws, (G[9], G[10], G[11]), (u0, u1, u2),
                                               (u0 / mag, u1 / mag, u2 / mag), mag)
        ws.membership = P
        if self.motion == "rigid" and self._pivoted:
            ws.own_turn = True
        c = ws.speeds[0] * dt
        if self.motion == "rigid" and self.mode == "scale" and self.scale_by == "parts":
            p, Pk = (G[9], G[10], G[11]), P.tolist()
            return rigid_step(F, G, (u0 * c, u1 * c, u2 * c), Pk, self.model.fields, ws.scale,
                              lambda v: self._part_scale(p, v, Pk), self._turned_away(G, ws), self.arrive)
        d = (s0 * c, s1 * c, s2 * c)  # the frame's displacement
        if self.motion == "rigid":
            return rigid_step(F, G, d, P.tolist(), self.model.fields, wound=self._turned_away(G, ws),
                              arrive=self.arrive)
        return se3.translate_flat(F, *d)

    def _turned_away(self, G: Flat, ws: Workspace) -> Vec3 | None:
        """The axis (unit, object frame) about which the frame at pose G is turned
        further than ``MAX_TURN`` from the mean orientation of the demonstration points
        near it; None when it is not (or none is near). The neighbour orientation leaves
        such a frame as it is (:class:`~sctd.skill.constraints.NeighbourOrientation`), and
        :func:`rigid_step` moves it along the arc of a field that turns about a far axis
        or centre (no ``pivot``: a door's hinge, 30 cm from the handle) without turning
        it: the demonstrations' turn would take the wrist on from where no demonstration
        held it, into its limits (traced: the cabinet's last joint, the oven's sixth),
        and the grasp holds the handle either way. A field that turns the hand about a
        point of its own (a ``pivot``: a bottle's opening) still turns it: that turn is
        the task, and moving the point instead would carry the opening off the mug."""
        nb = ws.neighbours[self.model_file]
        mean = nb.mean_orientation(nb.query(G[9:], self.max_n, self.max_d))
        if mean is None:
            return None
        gx, gy, gz, gw = mean
        fx, fy, fz, fw = se3.quaternion_from_flat(G)
        # the turn from the frame to the mean, q_mean * q_frame^-1 (as the constraint's)
        cw = gw * fw + gx * fx + gy * fy + gz * fz
        cx = -gw * fx + gx * fw - gy * fz + gz * fy
        cy = -gw * fy + gy * fw - gz * fx + gx * fz
        cz = -gw * fz + gz * fw - gx * fy + gy * fx
        vn = math.sqrt(cx * cx + cy * cy + cz * cz)
        if vn < 1e-12 or 2.0 * math.atan2(vn, abs(cw)) <= MAX_TURN:
            return None
        return cx / vn, cy / vn, cz / vn

    def _step(self, ws: Workspace, p: Vec3, u: Vec3, unit: Vec3, mag: float
              ) -> tuple[Array, Vec3, float]:
        """The fields' membership at ``p``, the frame's step at full speed and its scale."""
        nb = ws.neighbours[self.model_file]
        P = nb.membership(p, self.max_n, self.max_d)
        fields = self.model.fields
        agree = None
        if self.combine == "intent":
            agree = self._agreements(p, unit)
            P = intent_membership(P.tolist(), nb.prior.tolist(), agree, self.intent_kappa)
        if self.mode == "blend":
            return P, self._blend(p, unit, mag, P), 1.0
        if self.combine == "most_probable":
            s = fields[int(np.argmax(P))].agreement3(p, unit)
            s = abs(s) if self.direction == "both" else s
        else:
            if agree is None:
                agree = self._agreements(p, unit)
            Pk = P.tolist()
            s = sum(Pk[k] * a for k, a in enumerate(agree))
        scale = min(1.0, max(self.min_v, float(sigmoid(s, self.k_s))))
        return P, (u[0] * scale, u[1] * scale, u[2] * scale), scale

    def _part_scale(self, p: Vec3, v: Vec3, P: Sequence[float]) -> float:
        """The scaling (eqs. 4.31-4.34) of a part ``v`` of the frame's displacement at
        ``p``: its direction's agreement with the fields, weighted by the membership
        ``P`` the whole push was given (the most probable field's alone with
        ``most_probable``)."""
        n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        if n < 1e-15:
            return 1.0
        agree = self._agreements(p, (v[0] / n, v[1] / n, v[2] / n))
        if self.combine == "most_probable":
            s = agree[max(range(len(P)), key=P.__getitem__)]
        else:
            s = sum(pk * a for pk, a in zip(P, agree, strict=True))
        return min(1.0, max(self.min_v, float(sigmoid(s, self.k_s))))

    def _agreements(self, p: Vec3, unit: Vec3) -> list[float]:
        """Each field's agreement with the unit command (both ways along it, with
        ``direction: both``)."""
        agree = [f.agreement3(p, unit) for f in self.model.fields]
        return [abs(a) for a in agree] if self.direction == "both" else agree

    def _blend(self, p: Vec3, unit: Vec3, mag: float, P: Array) -> Vec3:
        """Eq. 4.35: the command's direction bent towards the fields' (the step at full
        speed); with ``direction: both`` towards each field's way the command goes."""
        p_a, unit_a = np.array(p), np.array(unit)
        bend = np.zeros(3)
        for k, f in enumerate(self.model.fields):
            g = f.guided_direction(p_a, unit_a)
            if self.direction == "both" and float(g @ unit_a) < 0.0:
                g = -g
            bend += P[k] * g
        direction = unit_a + self.blend * bend
        dn = float(np.linalg.norm(direction))
        direction = direction / dn if dn > 1e-6 else unit_a
        x, y, z = (direction * mag).tolist()
        return x, y, z

