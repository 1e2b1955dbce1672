"""Seeded demonstrations with ground truth for tasks shaped as the two thesis tasks (Ch.
5.2, 5.3), and two shapes of no task file.

Pure numpy (and the task files, read by :mod:`sctd.task`). Every demonstration is
the end-effector pose ``T_obj_ee`` over time in the task object's frame, sampled at
``rate`` Hz, with Gaussian noise and optional gross outliers, plus the truth the
learner should recover. :func:`generate` takes a task (its name or file,
:func:`sctd.task.find_task`) and makes the shape its file describes, with the task's
object, names and geometry; or ``crank`` or ``wipe``:

*tilt*, a task whose held object has contents (pour: object ``mug``, origin at the
centre of the mug's opening, z up). The end-effector's z axis is the held object's
axis and its outlet sits where the task file's held frame puts it (the bottle's tip,
``[0, 0, 0.12]`` in the ee frame: the truth ``tip_offset``). *carry*: the bottle,
upright, is translated along a straight line until its tip reaches the tilt point,
the goal of the intent's reach that comes before its tilt (5 cm above the opening);
then the tilt (the phase is named as the intent's tilt step): the bottle rotates about
its tip, about the ee's y axis, tilting its top towards the mug. In the tip frame the
tilt is a rotation only; the ee moves on a sphere about the tilt point (the truth
``sphere_centre``).

``crank`` (no task file; object ``crank``: origin on the crank's vertical axis at the
handle's height, z up; the handle starts on +x at the radius, 12-20 cm, drawn once per
task from the seed). *reach*: translate to the handle from in front and above; *turn*:
the hand, holding the handle, goes round the axis counter-clockwise (seen from above)
by 90-180 deg, turning with it (its yaw follows the crank), so the axis is fixed in
the hand's frame. A fixed-axis rotation: the truth is a cylinder (``axis``,
``point``).

``wipe`` (no task file; object ``table``: origin at the middle of the stroke, z up).
*reach*: translate down to the table; *wipe*: an S-shaped stroke over it, ``y = A
sin(2 pi x / L)`` over one wavelength ``L`` (25-30 cm) with ``A`` 5 cm, the same
stroke in every demonstration up to +-5 mm: its direction swings by +-50 deg, none of
the three shapes (the truth is ``general``).

*pull*, a task with a prismatic joint (drawer: object ``drawer_handle``, origin at
the grasp point of the *closed* drawer, x out of the drawer, z up; the frame stays
where the closed handle was, so the pull shows as motion along +x). *reach*:
translate to the handle from above and in front while the hand turns to its grasp
orientation; *pull*: translate along +x.

The speed profiles do not stop between phases (the carry ends at its mean speed and
the pour starts at it), as a person moves.

Run ``python -m sctd_sim.demogen pour OUT_DIR --n-demos 10 --seed 0`` to write CSVs
``demo_00.csv ...`` (``t,x,y,z,qx,qy,qz,qw``) and ``truth.json``.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sctd import se3
from sctd.app import add_deprecated_alias
from sctd.task import Task, find_task
from sctd.task.demos import DEMOS_FILE, DemosInfo
from sctd.task.kinds.reach import Reach
from sctd.task.kinds.tilt import Tilt

Array = NDArray[np.float64]

SHAPES = ("tilt", "pull", "crank", "wipe")
FIELD_TRUTH = {"tilt": ("translation", "sphere"), "pull": ("translation", "translation"),
               "crank": ("translation", "cylinder"), "wipe": ("translation", "general")}
"""The kind of field each phase of a shape is (``general``: none of the three shapes)."""


@dataclass(frozen=True)
class Kind:
    """What :func:`generate` makes for one name: the shape of the motion, and the names
    and geometry its truth reports.

    ``tip_offset`` (the outlet in the ee frame) and ``tilt_point`` (where the outlet
    tilts, in the object's frame), m: the tilt's alone.
    """

    name: str
    shape: str
    object: str
    phases: tuple[str, str]
    tip_offset: Array | None = None
    tilt_point: Array | None = None

    @property
    def fields(self) -> tuple[str, str]:
        """The kind of field each phase is."""
        return FIELD_TRUTH[self.shape]


SYNTHETIC = {"crank": Kind("crank", "crank", "crank", ("reach", "turn")),
             "wipe": Kind("wipe", "wipe", "table", ("reach", "wipe"))}
"""The kinds of no task file: their objects and geometry are the generator's own."""


def kind_of(t: Task) -> Kind:
    """The kind :func:`generate` makes for task ``t``: a tilt when its held object has
    contents, a pull when it has a prismatic joint (``crank`` and ``wipe``, of no task
    file, are :data:`SYNTHETIC`).

    Raises
    ------
    ValueError
        A task of neither shape.
    """
    held = t.scene.held
    if held is not None and held.contents is not None:
        return _tilt_kind(t)
    joint = next((j for j in t.scene.joints.values() if j.kind == "prismatic"), None)
    if joint is not None:
        return Kind(t.name, "pull", t.object, ("reach", "pull"))
    raise ValueError(f"{t.file or t.name}: the generator makes demonstrations of a task whose held "
                     "object's contents are tilted out or whose prismatic joint is pulled; this one has "
                     "neither")


def _tilt_kind(t: Task) -> Kind:
    """A tilt: the outlet as the held frame puts it, the tilt point as the goal of the
    intent's reach with that frame before its tilt, the tilt's phase named as its step."""
    held = t.scene.held
    assert held is not None and held.contents is not None
    outlet = held.contents.outlet
    k = next((i for i, s in enumerate(t.intent) if isinstance(s.action, Tilt)), None)
    reach = next((s.action for s in reversed(t.intent[:k or 0]) if isinstance(s.action, Reach)), None)
    if k is None or reach is None or reach.frame() != outlet or reach.to is None:
        raise ValueError(f"{t.file or t.name}: intent: the generator tilts the held object about its "
                         f"outlet {outlet!r} at the goal of a reach with that frame before a tilt step")
    return Kind(t.name, "tilt", t.object, ("carry", t.intent[k].name),
                tip_offset=np.array(held.frames[outlet][:3, 3], dtype=float),
                tilt_point=np.array(reach.to, dtype=float))


@dataclass
class GeneratedDemo:
    """One generated demonstration.

    ``poses`` (n, 7) ``T_obj_ee`` with noise and outliers; ``clean`` (n, 7) without;
    ``phase`` (n - 1,) the phase index of each displacement (rows i -> i + 1);
    ``outlier_rows`` indices of rows replaced by gross outliers.
    """

    name: str
    t: Array
    poses: Array
    clean: Array
    phase: NDArray[np.int64]
    outlier_rows: NDArray[np.int64]
    info: dict = field(default_factory=dict)


@dataclass
class DemoSet:
    """Demonstrations of one task plus the truth shared by all of them, and the shape
    they were made with (:data:`SHAPES`)."""

    task: str
    demos: list[GeneratedDemo]
    truth: dict
    shape: str = ""


def _carry_profile(tau: Array) -> Array:
    """s(0) = 0, s'(0) = 0, s(1) = 1, s'(1) = 1 (ends at its mean speed)."""
    return 2.0 * tau**2 - tau**3


def _final_profile(tau: Array) -> Array:
    """s(0) = 0, s'(0) = 1, s(1) = 1, s'(1) = 0 (starts at its mean speed)."""
    return 1.0 - _carry_profile(1.0 - tau)


def _rot_z(a: float) -> Array:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _sample_times(durations: tuple[float, float], rate: float) -> tuple[Array, NDArray[np.int64]]:
    total = durations[0] + durations[1]
    n = int(np.floor(total * rate)) + 1
    t = np.arange(n) / rate
    # Displacement i (t_i -> t_{i+1}) belongs to phase 1 once it ends after the switch.
    phase = (t[1:] > durations[0] + 1e-12).astype(np.int64)
    return t, phase


def _corrupt(rng: np.random.Generator, clean: Array, noise: float, rot_noise: float,
             outliers: float) -> tuple[Array, NDArray[np.int64]]:
    n = len(clean)
    T = se3.transform_from_pose(clean)
    pos = T[:, :3, 3] + rng.normal(0.0, noise, (n, 3))
    R = T[:, :3, :3] @ se3.matrix_from_rotvec(rng.normal(0.0, rot_noise, (n, 3)))
    rows = np.zeros(0, dtype=np.int64)
    if outliers > 0 and n > 6:
        k = round(outliers * n)
        rows = np.sort(rng.choice(np.arange(2, n - 2), size=min(k, n - 4), replace=False))
        dirs = rng.normal(size=(len(rows), 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        pos[rows] += dirs * rng.uniform(0.03, 0.10, (len(rows), 1))
        axes = rng.normal(size=(len(rows), 3))
        axes /= np.linalg.norm(axes, axis=1, keepdims=True)
        R[rows] = R[rows] @ se3.matrix_from_rotvec(axes * rng.uniform(0.2, 0.8, (len(rows), 1)))
    q = se3.quaternion_from_matrix(R)
    return np.concatenate([pos, q], axis=1), rows.astype(np.int64)


def _tilt_demo(rng: np.random.Generator, rate: float, tilt_jitter: float, tip_offset: Array,
               tilt_point: Array) -> tuple:
    phi = rng.uniform(-np.pi / 4, np.pi / 4)  # approach azimuth, from the +x side
    dist = rng.uniform(0.25, 0.35)
    height = rng.uniform(0.0, 0.15)
    P = tilt_point + rng.normal(0.0, tilt_jitter, 3) if tilt_jitter > 0 else tilt_point.copy()
    start_tip = P + np.array([dist * np.cos(phi), dist * np.sin(phi), height])
    # Upright bottle (ee z up), ee x horizontal towards the mug (+- 10 deg of yaw).
    yaw = phi + np.pi + rng.uniform(-np.radians(10), np.radians(10))
    R0 = _rot_z(yaw)
    theta_max = rng.uniform(np.radians(100), np.radians(130))
    v_carry = rng.uniform(0.08, 0.12)
    omega = rng.uniform(0.5, 0.8)
    d1 = float(np.linalg.norm(P - start_tip)) / v_carry
    d2 = theta_max / omega
    t, phase = _sample_times((d1, d2), rate)
    poses = np.empty((len(t), 7))
    for i, ti in enumerate(t):
        if ti <= d1:
            s = _carry_profile(np.array(ti / d1))
            tip = start_tip + s * (P - start_tip)
            R = R0
        else:
            s = _final_profile(np.array(min(1.0, (ti - d1) / d2)))
            R = R0 @ se3.matrix_from_rotvec(np.array([0.0, s * theta_max, 0.0]))
            tip = P
        p_ee = tip - R @ tip_offset
        poses[i, :3] = p_ee
        poses[i, 3:] = se3.quaternion_from_matrix(R)
    info = {"tilt_point": P.tolist(), "tilt_axis": (R0 @ np.array([0.0, 1.0, 0.0])).tolist(),
            "tilt_angle": float(theta_max),
            "carry_direction": ((P - start_tip) / np.linalg.norm(P - start_tip)).tolist()}
    return t, poses, phase, info


def _pull_demo(rng: np.random.Generator, rate: float) -> tuple:
    start = np.array([rng.uniform(0.20, 0.30), rng.uniform(-0.06, 0.06), rng.uniform(0.08, 0.14)])
    pull = rng.uniform(0.20, 0.30)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    w0 = axis * rng.uniform(np.radians(5), np.radians(15))  # start orientation offset
    v_reach = rng.uniform(0.08, 0.12)
    v_pull = rng.uniform(0.06, 0.10)
    d1 = float(np.linalg.norm(start)) / v_reach
    d2 = pull / v_pull
    t, phase = _sample_times((d1, d2), rate)
    poses = np.empty((len(t), 7))
    for i, ti in enumerate(t):
        if ti <= d1:
            s = float(_carry_profile(np.array(ti / d1)))
            p = (1.0 - s) * start
            R = se3.matrix_from_rotvec((1.0 - s) * w0)
        else:
            s = float(_final_profile(np.array(min(1.0, (ti - d1) / d2))))
            p = np.array([s * pull, 0.0, 0.0])
            R = np.eye(3)
        poses[i, :3] = p
        poses[i, 3:] = se3.quaternion_from_matrix(R)
    info = {"reach_direction": (-start / np.linalg.norm(start)).tolist(), "pull_length": pull}
    return t, poses, phase, info


def _crank_demo(rng: np.random.Generator, rate: float, radius: float) -> tuple:
    handle = np.array([radius, 0.0, 0.0])
    start = handle + np.array([rng.uniform(0.15, 0.25), rng.uniform(-0.06, 0.06),
                               rng.uniform(0.08, 0.14)])
    turn = rng.uniform(np.pi / 2, np.pi)
    v_reach = rng.uniform(0.08, 0.12)
    omega = rng.uniform(0.4, 0.7)  # rad/s: 5-8 cm/s at the handle
    d1 = float(np.linalg.norm(start - handle)) / v_reach
    d2 = turn / omega
    t, phase = _sample_times((d1, d2), rate)
    # The hand faces the axis (ee x towards it) and keeps facing it as it turns.
    R0 = _rot_z(np.pi)
    poses = np.empty((len(t), 7))
    for i, ti in enumerate(t):
        if ti <= d1:
            s = float(_carry_profile(np.array(ti / d1)))
            p, R = start + s * (handle - start), R0
        else:
            a = float(_final_profile(np.array(min(1.0, (ti - d1) / d2)))) * turn
            p, R = _rot_z(a) @ handle, _rot_z(a) @ R0
        poses[i, :3] = p
        poses[i, 3:] = se3.quaternion_from_matrix(R)
    info = {"reach_direction": ((handle - start) / np.linalg.norm(handle - start)).tolist(),
            "turn_angle": turn}
    return t, poses, phase, info


def _wipe_demo(rng: np.random.Generator, rate: float, length: float) -> tuple:
    amp = 0.05
    shift = rng.normal(0.0, 0.005, 3) * np.array([1.0, 1.0, 0.0])
    x0 = np.array([-length / 2, 0.0, 0.0]) + shift
    start = x0 + np.array([rng.uniform(-0.03, 0.0), rng.uniform(-0.02, 0.02), rng.uniform(0.18, 0.24)])
    v_reach = rng.uniform(0.08, 0.12)
    v_wipe = rng.uniform(0.06, 0.09)
    # Arc length of one wavelength of the S, for a near-constant speed along it.
    xs = np.linspace(0.0, length, 2001)
    ys = amp * np.sin(2 * np.pi * xs / length)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(xs), np.diff(ys)))])
    d1 = float(np.linalg.norm(x0 - start)) / v_reach
    d2 = float(arc[-1]) / v_wipe
    t, phase = _sample_times((d1, d2), rate)
    poses = np.empty((len(t), 7))
    poses[:, 3:] = [0.0, 0.0, 0.0, 1.0]
    for i, ti in enumerate(t):
        if ti <= d1:
            s = float(_carry_profile(np.array(ti / d1)))
            poses[i, :3] = start + s * (x0 - start)
        else:
            s = float(_final_profile(np.array(min(1.0, (ti - d1) / d2)))) * arc[-1]
            x = float(np.interp(s, arc, xs))
            poses[i, :3] = x0 + np.array([x, amp * np.sin(2 * np.pi * x / length), 0.0])
    info = {"reach_direction": ((x0 - start) / np.linalg.norm(x0 - start)).tolist()}
    return t, poses, phase, info


def generate(task: Task | Kind, n_demos: int = 10, noise: float = 0.001,
             rot_noise: float | None = None, outliers: float = 0.0, rate: float = 50.0,
             seed: int = 0, tilt_jitter: float = 0.0) -> DemoSet:
    """Generate ``n_demos`` demonstrations of ``task`` (a task, :func:`kind_of`, or a
    kind of :data:`SYNTHETIC`).

    Parameters
    ----------
    task : Task or Kind
    n_demos : int
    noise : float
        Standard deviation of the Gaussian position noise (m).
    rot_noise : float, optional
        Standard deviation of the rotation noise (rad, per axis); default ``noise``
        read as radians (1 mm -> 1 mrad).
    outliers : float
        Fraction of rows replaced by gross outliers (3-10 cm and 0.2-0.8 rad away).
    rate : float
        Samples per second.
    seed : int
        Seed of the numpy ``Generator``; the same arguments give the same data.
    tilt_jitter : float
        Standard deviation (m) of the tilt point between demonstrations (tilt only).
    """
    kind = task if isinstance(task, Kind) else kind_of(task)
    if n_demos < 1 or rate <= 0 or noise < 0 or not 0 <= outliers < 0.5:
        raise ValueError("need n_demos >= 1, rate > 0, noise >= 0, 0 <= outliers < 0.5")
    rng = np.random.default_rng(seed)
    rn = noise if rot_noise is None else rot_noise
    radius = float(rng.uniform(0.12, 0.20)) if kind.shape == "crank" else 0.0
    length = float(rng.uniform(0.25, 0.30)) if kind.shape == "wipe" else 0.0
    demos = []
    for k in range(n_demos):
        t, clean, phase, info = _clean_demo(kind, rng, rate, tilt_jitter, radius, length)
        poses, rows = _corrupt(rng, clean, noise, rn, outliers)
        demos.append(GeneratedDemo(f"demo_{k:02d}.csv", t, poses, clean, phase, rows, info))
    truth = _task_truth(kind, demos, radius, length)
    truth.update({
        "task": kind.name, "object": kind.object, "fields": list(kind.fields),
        "phases": list(kind.phases),
        "labels": {d.name: d.phase.tolist() for d in demos},
        "outlier_rows": {d.name: d.outlier_rows.tolist() for d in demos},
        "params": {"n_demos": n_demos, "noise": noise, "rot_noise": rn, "outliers": outliers,
                   "rate": rate, "seed": seed, "tilt_jitter": tilt_jitter},
    })
    return DemoSet(kind.name, demos, truth, kind.shape)


def _clean_demo(kind: Kind, rng: np.random.Generator, rate: float, tilt_jitter: float,
                radius: float, length: float) -> tuple:
    """One noise-free demonstration of ``kind``: ``(t, poses, phase, info)``."""
    if kind.shape == "tilt":
        assert kind.tip_offset is not None and kind.tilt_point is not None
        return _tilt_demo(rng, rate, tilt_jitter, kind.tip_offset, kind.tilt_point)
    if kind.shape == "pull":
        return _pull_demo(rng, rate)
    if kind.shape == "crank":
        return _crank_demo(rng, rate, radius)
    return _wipe_demo(rng, rate, length)


def _task_truth(kind: Kind, demos: list[GeneratedDemo], radius: float, length: float) -> dict:
    """What the demonstrations of ``kind`` were generated from, the part that depends on
    its shape: its directions and its geometry (tilt point, crank axis, wipe length)."""
    if kind.shape == "tilt":
        assert kind.tip_offset is not None
        dirs = np.array([d.info["carry_direction"] for d in demos])
        centre = np.mean([d.info["tilt_point"] for d in demos], axis=0)
        return {"sphere_centre": centre.tolist(), "tip_offset": kind.tip_offset.tolist(),
                "directions": {"carry": _unit_mean(dirs).tolist()},
                "tilt_axes": {d.name: d.info["tilt_axis"] for d in demos}}
    dirs = np.array([d.info["reach_direction"] for d in demos])
    truth: dict = {"directions": {"reach": _unit_mean(dirs).tolist()}}
    if kind.shape == "pull":
        truth["directions"]["pull"] = [1.0, 0.0, 0.0]
    elif kind.shape == "crank":
        truth.update({"axis": [0.0, 0.0, 1.0], "point": [0.0, 0.0, 0.0], "radius": radius,
                      "axis_ee_offset": [radius, 0.0, 0.0]})
    else:
        truth["length"] = length
    return truth


def _unit_mean(v: Array) -> Array:
    m = v.mean(axis=0)
    return m / np.linalg.norm(m)


def write_demo_set(demo_set: DemoSet, directory: str | Path, digits: int = 6) -> list[Path]:
    """Write ``demo_XX.csv`` files, ``truth.json`` and, for a task's demonstrations,
    ``demos.yaml`` (what they are of: :class:`~sctd.learn.demos.DemosInfo`) into
    ``directory`` (created)."""
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for d in demo_set.demos:
        p = out / d.name
        with p.open("w", newline="") as fh:
            fh.write("t,x,y,z,qx,qy,qz,qw\n")
            fmt = ",".join([f"%.{digits}f"] * 8) + "\n"
            for ti, row in zip(d.t, d.poses, strict=True):
                fh.write(fmt % (ti, *row))
        paths.append(p)
    (out / "truth.json").write_text(json.dumps(demo_set.truth, indent=1) + "\n")
    task, obj = demo_set.truth.get("task"), demo_set.truth.get("object")
    if task and obj:
        (out / DEMOS_FILE).write_text(DemosInfo(task, obj).to_yaml())
    return paths


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sctd_sim.demogen", description=__doc__.split("\n\n")[0])
    ap.add_argument("task", help="a task's name or file (its held contents tilted out, or its joint "
                                 "pulled), or crank or wipe")
    ap.add_argument("out", type=Path, help="output directory (CSV files and truth.json)")
    ap.add_argument("--n-demos", type=int, default=10)
    ap.add_argument("--noise", type=float, default=0.001, help="position noise std (m)")
    ap.add_argument("--rot-noise", type=float, default=None, help="rotation noise std (rad)")
    ap.add_argument("--outliers", type=float, default=0.0, help="fraction of outlier rows")
    ap.add_argument("--rate", type=float, default=50.0, help="samples per second")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tilt-jitter", type=float, default=0.0,
                    help="standard deviation (m) of the tilt point between demonstrations (tilt only; "
                         "default %(default)s)")
    add_deprecated_alias(ap, "--pour-jitter", dest="tilt_jitter", instead="--tilt-jitter", type=float)
    args = ap.parse_args(argv)
    try:
        kind = SYNTHETIC.get(args.task) or kind_of(find_task(args.task))
    except ValueError as e:  # (a TaskError is a ValueError)
        ap.error(f"task: {e}")
    ds = generate(kind, n_demos=args.n_demos, noise=args.noise, rot_noise=args.rot_noise,
                  outliers=args.outliers, rate=args.rate, seed=args.seed,
                  tilt_jitter=args.tilt_jitter)
    paths = write_demo_set(ds, args.out)
    print(f"wrote {len(paths)} demonstrations and truth.json to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
