"""Turns in place: a gripper phase in which the demonstrations turned the hand about an
axis while its origin stood still (a tap's handle, a knob, a key), learned as a field.

The thesis' vector fields (Ch. 4.2) are fields of the hand origin's velocity. A turn in
place has none: the origin stays on the handle while the hand turns, the preprocessing
(by distance travelled) keeps nothing of it, and RANSAC has nothing to fit. The learner
before this fitted a tap's approach and then copied the approach's mapping into the
phase that holds the handle, and every trial was stuck turning.

A point of the hand off the axis does move: on a circle about it. So the phase is
learned as a :class:`~sctd.skill.fields.CylinderField` of a *lever point*, a fixed
offset of the hand perpendicular to the axis, with the hand's origin as the field's
``pivot``. Driven with rigid motion (the door's swing, :mod:`sctd.skill.mappings`), a
push along the circle at the lever point turns the hand about the axis through its
origin, which stays where it is. The lever's length is the skill's speed caps' ratio
(``max_linear_speed / max_angular_speed``): a full push moves the lever point at the
linear cap and turns the hand at the angular one.

A phase is a turn in place when every demonstration turns by :data:`TURN_MIN` or more
in it, about axes within :data:`AXIS_AGREE` of their mean, with its origin within
:data:`STILL` (RMS) of where it stood. Otherwise the phase stays as it was learned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import se3
from ..skill.fields import CylinderField
from ..skill.modelfile import VectorFieldModel
from .demos import Demo
from .gripper import GripperPlan

Array = NDArray[np.float64]
TURN_MIN = math.radians(20)  # a phase turning less than this (in any demonstration) is not a turn
AXIS_AGREE = math.radians(20)  # each demonstration's axis within this of the mean
STILL = 0.01  # m: the origin's RMS distance from where it stood in the phase, in each demonstration


@dataclass(frozen=True)
class TurnInPlace:
    """The turn of gripper phase ``phase``: about the unit ``axis`` (object frame, the
    demonstrated sense by the right-hand rule) through ``centre`` (where the origins
    stood), driven at the ee offset ``lever`` (perpendicular to the axis). ``points``
    and ``quaternions`` are the lever point's poses in the demonstrations (object frame),
    ``angles`` each demonstration's turn (rad), ``spread`` the largest RMS distance of a
    demonstration's origin from where it stood (m), ``sigma`` the RMS angle between the
    lever point's motion and the field's (rad)."""

    phase: int
    axis: Array
    centre: Array
    lever: Array
    points: Array
    quaternions: Array
    angles: Array
    spread: float
    sigma: float

    def field(self) -> CylinderField:
        """The cylinder field of the lever point, its pivot the hand's origin."""
        return CylinderField(point=self.centre, axis=self.axis, pivot=-self.lever, weight=1.0,
                             sigma=self.sigma, inliers=len(self.points))

    def model(self) -> VectorFieldModel:
        """The field with the lever point's poses it was learned from (a model file)."""
        return VectorFieldModel(fields=(self.field(),), points=self.points, quaternions=self.quaternions,
                                responsibilities=np.ones((len(self.points), 1)))


def turns_in_place(demos: list[Demo], plan: GripperPlan, lever_length: float, spacing: float
                   ) -> dict[int, TurnInPlace]:
    """The phases of ``plan`` (by index) in which ``demos`` turn in place (the module's
    docstring), each learned with a lever of ``lever_length`` m; the lever point's poses
    are kept every ``spacing`` m of its path (as the vector fields' points are)."""
    out = {}
    for p in range(len(plan.events) + 1):
        rows = [_phase_rows(plan.phases[d.name], p) for d in demos]
        if all(len(r) >= 2 for r in rows):
            turn = _turn(p, [d.poses[r] for d, r in zip(demos, rows, strict=True)], lever_length, spacing)
            if turn is not None:
                out[p] = turn
    return out


def _phase_rows(phase_of: list[int], p: int) -> NDArray[np.int64]:
    """The rows of phase ``p``: both ends of each of its displacements (row i -> i + 1)."""
    i = np.flatnonzero(np.asarray(phase_of) == p)
    return np.unique(np.concatenate([i, i + 1])) if len(i) else i


def _turn(p: int, poses: list[Array], lever_length: float, spacing: float) -> TurnInPlace | None:
    """The turn in place of phase ``p`` from each demonstration's poses (k, 7) in it, or
    None when they do not turn in place."""
    R = [se3.matrix_from_quaternion(q[[0, -1], 3:]) for q in poses]  # each demonstration's first and last
    turns = [se3.rotvec_from_matrix(last @ first.T) for first, last in R]
    angles = np.array([float(np.linalg.norm(w)) for w in turns])
    spread = max(float(np.sqrt(np.mean(np.sum((q[:, :3] - q[:, :3].mean(0)) ** 2, axis=1)))) for q in poses)
    if angles.min() < TURN_MIN or spread > STILL:
        return None
    units = np.array([w / a for w, a in zip(turns, angles, strict=True)])
    axis = units.sum(0) / np.linalg.norm(units.sum(0))
    if np.min(units @ axis) < math.cos(AXIS_AGREE):
        return None
    lever = np.round(lever_length * _across(se3.matrix_from_quaternion(poses[0][0, 3:]).T @ axis), 6)
    centre = np.mean(np.concatenate([q[:, :3] for q in poses]), axis=0)
    kept = [_lever_poses(q, lever, spacing) for q in poses]
    points = np.concatenate([k[:, :3] for k in kept])
    field = CylinderField(point=centre, axis=axis)
    steps = [(k[:-1, :3], np.diff(k[:, :3], axis=0)) for k in kept if len(k) > 1]
    sigma = 0.3  # the fields' default, where no demonstration's lever point moved a spacing
    if steps:
        at, motion = (np.concatenate(x) for x in zip(*steps, strict=True))
        unit = motion / np.linalg.norm(motion, axis=1, keepdims=True)
        sigma = float(np.sqrt(np.mean(field.deviation_angles(at + 0.5 * motion, unit) ** 2)))
    return TurnInPlace(phase=p, axis=axis, centre=centre, lever=lever, points=points,
                       quaternions=np.concatenate([k[:, 3:] for k in kept]), angles=angles, spread=spread,
                       sigma=max(sigma, 0.01))


def _across(a_ee: Array) -> Array:
    """A unit direction of the hand perpendicular to ``a_ee`` (the axis in the ee frame):
    the hand's x axis with its part along the axis removed, or its y axis where x lies
    near the axis."""
    for e in np.eye(3)[:2]:
        d = e - float(e @ a_ee) * a_ee
        if np.linalg.norm(d) > 0.5:
            return d / np.linalg.norm(d)
    d = np.array([0.0, 0.0, 1.0]) - a_ee[2] * a_ee
    return d / np.linalg.norm(d)


def _lever_poses(q: Array, lever: Array, spacing: float) -> Array:
    """The lever point's poses (k, 7) along one demonstration's phase (its ee poses ``q``),
    one each ``spacing`` m of the lever point's path (the first always)."""
    R = se3.matrix_from_quaternion(q[:, 3:])
    pts = q[:, :3] + np.einsum("nij,j->ni", R, lever)
    keep, last = [0], pts[0]
    for i in range(1, len(pts)):
        if np.linalg.norm(pts[i] - last) >= spacing:
            keep.append(i)
            last = pts[i]
    return np.concatenate([pts[keep], q[keep, 3:]], axis=1)
