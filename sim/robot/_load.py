"""Load an arm URDF into an immutable Pinocchio model plus its limits, checked.

The shipped arm is ``edan_arm.urdf``; any other URDF whose chain from its root to the
end-effector frame is seven revolute joints with limits and masses loads too (``sctd sim
--urdf FILE --ee-frame NAME``, ``docs/sim-urdf.md``). What the simulator needs of it,
and so what :func:`load_arm_model` checks:

- the chain from the root (the world) to ``ee_frame`` is as many revolute joints as the
  CAN joint bus has joints (seven, ``sim/edan_joints.dbc``); joints off that chain
  (gripper fingers) are locked at the middle of their limits, their links' masses
  added to the link they hang from;
- every chain joint has position, velocity and torque limits (``<limit>``) within what
  the joint bus carries (measured positions within +-5.24 rad, velocities within
  +-6.55 rad/s, torques within +-204.7 N m), and a non-negative viscous friction
  (``<dynamics damping>``, 0 when absent);
- the moving links have mass (``<inertial>``): the simulator integrates the dynamics.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..canbus.layout import JointBusRanges, joint_bus_ranges

URDF_PATH = Path(__file__).with_name("edan_arm.urdf")
"""Path of the shipped URDF."""

EE_FRAME = "ee"
"""Name of the end-effector (hand tool centre point) frame of the shipped URDF."""

ARMATURE = np.array([0.20, 0.20, 0.10, 0.10, 0.05, 0.03, 0.03])
"""Reflected rotor inertia per joint, kg m^2 (motor inertia times gear ratio squared).

URDF has no field for it. Harmonic-drive joints of light-weight arms reflect 0.03 to
0.3 kg m^2; besides realism this keeps the light wrist links numerically well
conditioned at 1 kHz with explicit integration. Another arm's URDF gets the same unless
:func:`load_arm_model` is given its own.
"""

REST_POSTURE = np.deg2rad([0.0, 30.0, 0.0, -90.0, 0.0, 60.0, 0.0])
"""Default posture of the shipped arm, rad: elbow bent, hand in front of the base
pointing down."""

FORWARD_POSTURE = np.deg2rad([0.0, 50.0, 0.0, -100.0, 0.0, -40.0, 0.0])
"""Posture of the shipped arm with the hand in front pointing forward and down-tilted
(IK seed)."""

UP_POSTURE = np.deg2rad([-56.0, 84.0, -84.0, 111.0, -82.0, 87.0, 125.0])
"""Posture of the shipped arm with the hand in front pointing up, elbow out to the side
(IK seed for the scenes, whose hand points up; with the elbow in the vertical plane the
wrist pitch limit keeps an upward hand far from the base)."""

_REVOLUTE = {"JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned"}
_URDF_TYPE = {"JointModelRUBX": "continuous", "JointModelRUBY": "continuous",
              "JointModelRUBZ": "continuous", "JointModelRevoluteUnboundedUnaligned": "continuous",
              "JointModelPX": "prismatic", "JointModelPY": "prismatic", "JointModelPZ": "prismatic",
              "JointModelPrismaticUnaligned": "prismatic", "JointModelFreeFlyer": "floating",
              "JointModelPlanar": "planar"}


class ArmModelError(ValueError):
    """A URDF the simulator cannot drive: the message names the file and what is wrong.

    Attributes
    ----------
    part : str
        What is wrong: ``"ee_frame"`` (the URDF has no such frame), ``"armature"`` or
        ``"urdf"`` (the file).
    """

    def __init__(self, message: str, part: str = "urdf") -> None:
        super().__init__(message)
        self.part = part


@dataclass(frozen=True)
class ArmModel:
    """Immutable description of the arm shared by physics, controller and drives.

    Attributes
    ----------
    model : pinocchio.Model
        Kinematic and inertial model of the seven chain joints, with armature set.
        Never mutate after loading; every user keeps its own ``pinocchio.Data``
        workspace (``model.createData()``).
    ee_frame_id : int
        Index of the end-effector frame in ``model.frames``.
    q_lower, q_upper : ndarray, shape (7,)
        Joint position limits, rad.
    dq_max : ndarray, shape (7,)
        Joint velocity limits, rad/s.
    tau_max : ndarray, shape (7,)
        Joint torque limits, N m.
    damping : ndarray, shape (7,)
        Viscous joint friction, N m s / rad.
    rest : ndarray, shape (7,)
        Rest posture, rad: the shipped arm's :data:`REST_POSTURE`, another arm's middle
        of its limits.
    urdf_path : Path
        The URDF it was loaded from.
    ee_frame : str
        Name of the end-effector frame.
    seeds : tuple of ndarray, shape (7,) each
        Postures from which :func:`~sctd_sim.simulation.start_posture` tries inverse
        kinematics first (before its pseudo-random ones): the shipped arm's up, rest and
        forward postures; another arm's rest.
    seeds_tuned : bool
        Whether :attr:`seeds` were chosen by hand for the tasks (the shipped arm): then
        the first posture reached from them is a start posture; else the one furthest
        from the joint limits of all reached.
    """

    model: pin.Model
    ee_frame_id: int
    q_lower: np.ndarray
    q_upper: np.ndarray
    dq_max: np.ndarray
    tau_max: np.ndarray
    damping: np.ndarray
    rest: np.ndarray
    urdf_path: Path
    ee_frame: str
    seeds: tuple[np.ndarray, ...]
    seeds_tuned: bool

    @property
    def nq(self) -> int:
        """Number of joints."""
        return int(self.model.nq)

    @property
    def joint_names(self) -> list[str]:
        """Names of the actuated joints, base to tip."""
        return [str(n) for n in self.model.names[1:]]


def load_arm_model(urdf_path: str | Path = URDF_PATH, ee_frame: str = EE_FRAME, *,
                   armature: np.ndarray | None = None) -> ArmModel:
    """Build the arm model from a URDF, checked against what the simulator needs.

    Parameters
    ----------
    urdf_path : str or Path, optional
        URDF file; defaults to the shipped ``edan_arm.urdf``. Its root is the world.
    ee_frame : str, optional
        The frame sctd moves (the hand's tool centre point); default :data:`EE_FRAME`.
    armature : array_like, shape (7,), optional
        Reflected rotor inertia per chain joint, kg m^2; default :data:`ARMATURE`.

    Returns
    -------
    ArmModel
        The chain from the root to ``ee_frame`` (other joints locked, see the module
        docstring), with armature and all limits as arrays.

    Raises
    ------
    ArmModelError
        The file is not a URDF Pinocchio reads, has no frame ``ee_frame`` (a few frames
        it has are named), or its chain to it is not what the simulator drives (seven
        revolute joints with limits the joint bus carries, and masses); the message
        starts with the file.
    """
    path = Path(urdf_path)
    full = _read_urdf(path)
    model = _arm_chain(full, path, _ee_frame_id(full, path, ee_frame))
    bus = joint_bus_ranges()
    _check_joints(model, path, ee_frame, bus.n_joints)
    _check_limits(model, path, bus)
    _check_masses(model, path)
    model.armature = _armature(model, path, ARMATURE if armature is None else armature)
    shipped = path.resolve() == URDF_PATH.resolve()
    q_lower, q_upper = np.array(model.lowerPositionLimit), np.array(model.upperPositionLimit)
    rest = REST_POSTURE.copy() if shipped else 0.5 * (q_lower + q_upper)
    return ArmModel(
        model=model,
        ee_frame_id=int(model.getFrameId(ee_frame)),
        q_lower=q_lower,
        q_upper=q_upper,
        dq_max=np.array(model.velocityLimit),
        tau_max=np.array(model.effortLimit),
        damping=np.array(model.damping),
        rest=rest,
        urdf_path=path,
        ee_frame=ee_frame,
        seeds=(UP_POSTURE.copy(), rest, FORWARD_POSTURE.copy()) if shipped else (rest,),
        seeds_tuned=shipped,
    )


def _read_urdf(path: Path) -> pin.Model:
    """The whole model of the URDF at ``path`` (fixed base)."""
    if not path.is_file():
        raise ArmModelError(f"{path}: no such file")
    try:
        return pin.buildModelFromUrdf(str(path))
    except (ValueError, RuntimeError, OSError) as e:
        raise ArmModelError(f"{path}: not a URDF Pinocchio reads: {e}") from None


def _ee_frame_id(model: pin.Model, path: Path, ee_frame: str) -> int:
    """The index of frame ``ee_frame``; else an error naming the links furthest from the
    root (the end effectors it may have meant) and how many frames there are."""
    if model.existFrame(ee_frame):
        return int(model.getFrameId(ee_frame))

    def depth(i: int) -> int:  # frames between frame i and the root
        n = 0
        while i != 0 and n < len(model.frames):
            i, n = model.frames[i].parentFrame, n + 1
        return n

    links = [i for i, f in enumerate(model.frames) if f.type == pin.FrameType.BODY]
    links.sort(key=lambda i: -depth(i))  # deepest first (stable)
    names = ", ".join(model.frames[i].name for i in links[:8])
    raise ArmModelError(f"{path}: no frame {ee_frame!r} (its links furthest from the root: {names}; "
                        f"{len(model.frames)} frames in all)", part="ee_frame")


def _arm_chain(model: pin.Model, path: Path, frame_id: int) -> pin.Model:
    """``model`` reduced to the joints that move frame ``frame_id``: the others are
    locked at the middle of their limits (their neutral position when they have none),
    their links' inertias merged into the links they hang from."""
    chain = set(model.supports[model.frames[frame_id].parentJoint])
    locked = [j for j in range(1, model.njoints) if j not in chain]
    if not locked:
        return model
    q = pin.neutral(model)
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    for j in locked:
        i, n = model.joints[j].idx_q, model.joints[j].nq
        if n == 1 and np.isfinite(lower[i]) and np.isfinite(upper[i]):
            q[i] = 0.5 * (lower[i] + upper[i])
    try:
        return pin.buildReducedModel(model, locked, q)
    except (ValueError, RuntimeError) as e:
        names = ", ".join(model.names[j] for j in locked)
        raise ArmModelError(f"{path}: cannot lock the joints off the chain ({names}): {e}") from None


def _check_joints(model: pin.Model, path: Path, ee_frame: str, n_joints: int) -> None:
    """The chain is ``n_joints`` revolute joints with limits."""
    names = [str(n) for n in model.names[1:]]
    if len(names) != n_joints:
        raise ArmModelError(
            f"{path}: the chain from the root to {ee_frame!r} has {len(names)} joints "
            f"({', '.join(names) or 'none'}); the simulator drives {n_joints} revolute joints (its "
            "CAN joint bus, sim/edan_joints.dbc, has frames for that many)")
    for name, joint in zip(names, model.joints[1:], strict=True):
        kind = joint.shortname()
        if kind not in _REVOLUTE:
            what = _URDF_TYPE.get(kind, kind)
            extra = " (no position limits)" if what == "continuous" else ""
            raise ArmModelError(f"{path}: joint {name!r} is {what}{extra}; the simulator drives "
                                f"{n_joints} revolute joints with limits")


def _check_limits(model: pin.Model, path: Path, bus: JointBusRanges) -> None:
    """Every chain joint's limits exist and lie within what the joint bus carries, and its
    viscous friction is not negative."""
    rows = (("position", model.lowerPositionLimit, model.upperPositionLimit, bus.position, "rad"),
            ("velocity", -model.velocityLimit, model.velocityLimit, bus.velocity, "rad/s"),
            ("effort", -model.effortLimit, model.effortLimit, bus.torque, "N m"))
    for j, name in enumerate(model.names[1:]):
        for what, low, high, (bus_low, bus_high), unit in rows:
            lo, hi = float(low[j]), float(high[j])
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise ArmModelError(f"{path}: joint {name!r}: <limit> {what} missing or empty "
                                    f"([{lo:g}, {hi:g}] {unit}); the simulator needs it")
            if lo < bus_low or hi > bus_high:
                raise ArmModelError(
                    f"{path}: joint {name!r}: {what} limits [{lo:g}, {hi:g}] {unit} exceed what the "
                    f"joint bus carries ([{bus_low:g}, {bus_high:g}], sim/edan_joints.dbc)")
        if not model.damping[j] >= 0.0:
            raise ArmModelError(f"{path}: joint {name!r}: <dynamics damping> must not be negative, "
                                f"got {model.damping[j]:g}")


def _check_masses(model: pin.Model, path: Path) -> None:
    """The moving links have mass (the dynamics is integrated)."""
    moving = sum(float(model.inertias[j].mass) for j in range(1, model.njoints))
    if not moving > 0.0:
        raise ArmModelError(f"{path}: the links the joints move have no mass (<inertial>); the "
                            "simulator integrates the arm's dynamics and needs them")


def _armature(model: pin.Model, path: Path, armature: np.ndarray) -> np.ndarray:
    """``armature`` checked: one non-negative finite value per chain joint."""
    a = np.array(armature, dtype=float)
    if a.shape != (model.nv,) or not np.all(np.isfinite(a)) or np.any(a < 0.0):
        raise ArmModelError(f"{path}: armature: need {model.nv} non-negative values, got {a}",
                            part="armature")
    return a
