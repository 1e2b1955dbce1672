"""Feature frames found in the demonstrations (Ch. 4.2.7), for the linear learner.

The thesis' task list begins "identify feature frames and input mappings"; its linear
learner is given its frames. :func:`automatic_frames` finds them as the vector-field
learner does: the centre of a sphere field or a point on a cylinder's axis that stays
put in the hand's frame over the points the field explains (a bottle's opening the hand
turns about, the axis of a crank the hand goes round) is a frame of the hand. A
sphere's frame has the hand's orientation; a cylinder's has its z axis along the axis
(as the hand sees it), so a turn about it is one rotation axis of the frame.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import se3
from ..skill.fields import CylinderField
from .demos import Demo
from .preprocess import Preprocessing, preprocess
from .vf import VectorFieldLearner

Array = NDArray[np.float64]


@dataclass(frozen=True)
class FoundFrame:
    """A frame of the hand found in the demonstrations.

    ``pose`` [x, y, z, qx, qy, qz, qw] is ``T_ee_frame``; ``spread`` (m) the RMS
    distance of the field's centre or axis point from ``pose``'s position, seen from
    the hand, over the points the field explains; ``kind`` the field (sphere or
    cylinder) and ``position`` its centre or axis point in the object frame.
    """

    name: str
    kind: str
    pose: Array
    spread: float
    position: Array

    def summary(self) -> dict:
        return {"name": self.name, "kind": self.kind, "pose": [round(float(x), 6) for x in self.pose],
                "spread": round(self.spread, 6), "position": [round(float(x), 6) for x in self.position]}


def _z_to(axis: Array) -> Array:
    """A unit quaternion [x, y, z, w] turning the z axis onto the unit ``axis``."""
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.clip(z @ axis, -1.0, 1.0))
    w = np.cross(z, axis)
    s = float(np.linalg.norm(w))
    if s < 1e-9:
        return np.array([1.0, 0.0, 0.0, 0.0]) if c < 0 else np.array([0.0, 0.0, 0.0, 1.0])
    return se3.quaternion_from_matrix(se3.matrix_from_rotvec(w / s * np.arctan2(s, c)))


def automatic_frames(demos: list[Demo], preprocessing: Preprocessing | None = None,
                     learner: VectorFieldLearner | None = None,
                     max_spread: float = 0.02) -> list[FoundFrame]:
    """The hand's feature frames the demonstrations turned about.

    Parameters
    ----------
    demos : list of Demo
    preprocessing : Preprocessing, optional
        As for vector fields (their spacing, by position).
    learner : VectorFieldLearner, optional
        Unfitted; its defaults by default (fitted in place).
    max_spread : float
        A field's centre or axis point must stay within this RMS distance (m) of one
        point of the hand to be a frame of it.

    Returns
    -------
    list of FoundFrame
        Named as the vector-field learner names its candidate frames (``sphere0``,
        ``cylinder0``, ...), in its order.
    """
    preprocessing = Preprocessing() if preprocessing is None else preprocessing
    learner = VectorFieldLearner() if learner is None else learner
    prepared = preprocess(demos, preprocessing, preprocessing.vf_spacing, 0.0, translation_only=True)
    learner.fit([p.poses[:, :3] for p in prepared], [p.poses[:, 3:] for p in prepared])
    out = []
    # One candidate per sphere or cylinder field, in the order of the fields.
    rotational = [m for m, f in enumerate(learner.fields_) if f.type in ("sphere", "cylinder")]
    for m, c in zip(rotational, learner.candidate_frames_, strict=True):
        spread = c.get("ee_offset_spread")
        if spread is None or spread > max_spread:
            continue
        q = np.array([0.0, 0.0, 0.0, 1.0])
        f = learner.fields_[m]
        if isinstance(f, CylinderField):
            R = se3.matrix_from_quaternion(learner.quaternions_[learner.assignment_ == m])
            a = np.einsum("nji,j->ni", R, np.asarray(f.axis)).mean(axis=0)  # seen from the hand
            q = _z_to(a / np.linalg.norm(a))
        out.append(FoundFrame(c["name"], c["kind"], np.concatenate([c["ee_offset"], q]),
                              float(spread), np.asarray(c["position"], dtype=float)))
    return out


def frames_to_use(given: Mapping[str, object] | None, found: list[FoundFrame]) -> dict[str, Array]:
    """The candidate frames of a linear learning run: the given ones when there are any
    (they win), else the found ones."""
    if given:
        return {k: np.asarray(v, dtype=float) for k, v in given.items()}
    return {f.name: f.pose for f in found}
