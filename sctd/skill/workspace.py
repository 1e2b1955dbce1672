"""The per-tick data of one running skill: Pinocchio's ``data`` to the skill's ``model``.

A :class:`~sctd.skill.model.Skill` is immutable and shared; a :class:`Workspace` holds
what running it needs besides: its frames as flat transforms, its speeds, the KD-trees
of its model files (with their reuse caches), and what the last command left for
others to read. The element classes evaluate themselves against it, so it is made from
the skill's parts (its speeds, frames and model files), not from the skill: the
elements sit below the model that holds them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from .. import se3
from .frames import Frame
from .modelfile import VectorFieldModel
from .neighbours import Neighbours

Array = NDArray[np.float64]
Flat = se3.Flat


class FrameOffset:
    """A fixed offset ``T_ee_frame`` of a frame on the end-effector, as flat data."""

    __slots__ = ("R", "flat", "t")

    def __init__(self, T_ee_frame: Array):
        R = T_ee_frame[:3, :3]
        self.t: tuple[float, float, float] = tuple(T_ee_frame[:3, 3].tolist())
        self.R: tuple[float, ...] | None = None if np.allclose(R, np.eye(3), atol=1e-15) \
            else tuple(R.ravel().tolist())  # None: a pure translation
        self.flat = se3.flat_from_transform(T_ee_frame)

    def frame(self, F: Flat) -> Flat:
        """The frame's pose for the ee pose F (same parent as F)."""
        if self.R is not None:
            return se3.compose_flat(F, self.flat)
        a, b, c, d, e, f, g, h, i, x, y, z = F
        tx, ty, tz = self.t
        return (a, b, c, d, e, f, g, h, i, a * tx + b * ty + c * tz + x,
                           d * tx + e * ty + f * tz + y, g * tx + h * ty + i * tz + z)


class Workspace:
    """What running one skill needs beside the skill itself.

    Parameters
    ----------
    speeds : sequence of 6 floats
        The skill's :attr:`~sctd.skill.model.Limits.speeds`.
    frames : mapping of str to Frame
        The skill's frames, the built-in ones included.
    models : mapping of str to VectorFieldModel
        The skill's model files by relative path (:meth:`~sctd.skill.model.Skill.models`).

    Attributes
    ----------
    speeds : tuple of 6 floats
        The skill's speeds at full input per displacement axis (tx, ty, tz: m/s; rx,
        ry, rz: rad/s).
    offsets : dict of str to FrameOffset
        The frames on the end-effector (the ee itself included).
    fixed : dict of str to (Flat, Flat)
        The frames fixed in the object (the object itself included): their pose in the
        object frame and its inverse.
    neighbours : dict of str to Neighbours
        A KD-tree per model file of the skill, shared by the elements that read it.
    turn_budget : float
        How far (rad) a correction may turn the hand in the running command (infinite
        outside a command).
    own_turn : bool
        Whether a mapping of the running command turns the hand rigidly about a point
        of its own (a field's ``pivot``: a bottle's opening, a cup's rim): that turn is
        the task's, the person's to make.
    turn_axis : tuple of 3 floats or None
        The unit axis (object frame) about which the running command's input mappings
        turned the hand, where that is the person's own turn (:attr:`own_turn`); None
        otherwise, and outside a command.
    scale : float
        The vector-field scaling of the last command (1 when none applied; for status).
    membership : ndarray, shape (K,), or None
        ``P(F | p)`` (or ``P(F | p, u)``) of the fields of the last vector-field command
        (None before one; for evaluation and plots).
    grasped : bool or None
        Whether the gripper holds something, by the newest robot state's reading, for
        the ``gripper`` transitions; None when the robot reports no gripper or its state
        is stale (set by :meth:`~sctd.skill.engine.SkillEngine.update`).
    """

    def __init__(self, speeds: Sequence[float], frames: Mapping[str, Frame],
                 models: Mapping[str, VectorFieldModel]):
        self.speeds = tuple(speeds)
        self.offsets: dict[str, FrameOffset] = {}
        self.fixed: dict[str, tuple[Flat, Flat]] = {}
        for name, f in frames.items():
            if f.parent == "ee":
                self.offsets[name] = FrameOffset(f.T_parent_frame)
            else:
                F = se3.flat_from_transform(f.T_parent_frame)
                self.fixed[name] = (F, se3.invert_flat(F))
        self.neighbours = {rel: Neighbours(model) for rel, model in models.items()}
        self.turn_budget = math.inf
        self.own_turn = False
        self.turn_axis: tuple[float, float, float] | None = None
        self.scale = 1.0
        self.membership: Array | None = None
        self.grasped: bool | None = None

    def refresh(self) -> int:
        """:meth:`Neighbours.refresh` of every model file's neighbours (between ticks);
        how many answers were worked out ahead."""
        return sum(n.refresh() for n in self.neighbours.values())

    def frame_pose(self, F: Flat, frame: str) -> Flat:
        """Pose of the end-effector-attached ``frame`` for the ee pose F (F itself for a
        frame that is not on the end-effector)."""
        off = self.offsets.get(frame)
        return F if off is None else off.frame(F)
