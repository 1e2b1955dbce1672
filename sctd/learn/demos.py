"""Demonstrations: CSV reading with validation, preprocessing, DTW (Ch. 4.1.1, 5.1).

A demonstration is a CSV file with the header ``t,x,y,z,qx,qy,qz,qw`` (other columns
are ignored): the end-effector pose over time in the task object's frame
(``T_obj_ee``). Optionally, both or neither, ``gripper`` (the fingers' width, m) and
``grasped`` (0/1: they hold something), the hand's fingers (:data:`GRIPPER_COLUMNS`).
Optionally, the scene's other bodies: for each, seven columns ``<body>.x, <body>.y,
<body>.z, <body>.qx, <body>.qy, <body>.qz, <body>.qw``, its pose in the task object's
frame (``T_obj_body``; :attr:`Demo.bodies`), from which the hand in that body's frame is
``T_obj_body^-1 T_obj_ee`` (:meth:`Demo.poses_in`).
:func:`read_demos` reads a folder of them and either returns every demonstration or
raises :class:`DemoError` naming the file, the row (and column) and the reason; nothing
is half-loaded.

Preprocessing (pure functions on arrays): :func:`spike_mask` drops isolated gross
outliers (a Hampel filter; the thesis has none, Ch. 6), :func:`smooth_poses` averages
out sensor noise over a few samples, :func:`subsample_by_distance` keeps samples a
fixed tf-norm apart (Ch. 4.1.1), :func:`dtw` aligns two demonstrations with the
tf-norm (Ch. 5.1).

Beside the CSVs, a folder's ``demos.yaml`` says what they are demonstrations of
(:mod:`sctd.task.demos`).
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import uniform_filter1d

from .. import se3
from ..files import FileError, open_regular
from ..wire.codec import DEMO_BODY_FIELDS, MAX_DEMO_BODIES, name_problem

Array = NDArray[np.float64]

COLUMNS = ("t", "x", "y", "z", "qx", "qy", "qz", "qw")
GRIPPER_COLUMNS = ("gripper", "grasped")  # optional, both or neither
MAX_GRIPPER_WIDTH = 0.5  # m: the wire contract's (sctd.wire.codec.MAX_GRIPPER_WIDTH)
QUAT_TOLERANCE = 1e-3
MIN_SAMPLES = 10


class DemoError(ValueError):
    """A demonstration file is malformed: ``file: row N (line L): reason``."""

    def __init__(self, file: str, row: int | None, reason: str):
        self.file = file
        self.row = row
        self.reason = reason
        where = file if row is None else f"{file}: row {row} (line {row + 1})"
        super().__init__(f"{where}: {reason}")

    def __reduce__(self) -> tuple:  # it crosses a process (the learner trains in a child)
        return type(self), (self.file, self.row, self.reason)


@dataclass(frozen=True)
class Demo:
    """One demonstration: times (n,) and end-effector poses (n, 7) in the object frame,
    and, where it has the gripper's columns, the fingers' ``width`` (n,) in m and
    ``grasped`` (n,) of bool (None without them), and where it has other bodies'
    columns, ``bodies``: each body's pose (n, 7) in the object frame (``T_obj_body``;
    empty without them).

    Quaternions are normalised to the canonical hemisphere (qw >= 0).
    """

    name: str
    t: Array
    poses: Array
    width: Array | None = None
    grasped: NDArray[np.bool_] | None = None
    bodies: dict[str, Array] = field(default_factory=dict)

    @property
    def T(self) -> Array:
        """Homogeneous ``T_obj_ee`` (n, 4, 4)."""
        return se3.transform_from_pose(self.poses)

    def poses_in(self, body: str) -> Array:
        """The end-effector's poses (n, 7) in ``body``'s frame, ``T_body_ee = T_obj_body^-1
        T_obj_ee`` (qw >= 0): :attr:`poses` for the task object (any name not in
        :attr:`bodies`: a caller asks for a body it knows the demonstration has)."""
        if body not in self.bodies:
            return self.poses
        T = np.linalg.inv(se3.transform_from_pose(self.bodies[body])) @ self.T
        P = se3.pose_from_transform(T)
        P[:, 3:] *= np.where(P[:, 6:7] < 0.0, -1.0, 1.0)
        return P

    def select(self, index: NDArray[np.int64] | NDArray[np.bool_]) -> Demo:
        """The demonstration's rows ``index`` (an index array or a mask), every column."""
        return Demo(self.name, self.t[index], self.poses[index],
                    None if self.width is None else self.width[index],
                    None if self.grasped is None else self.grasped[index],
                    {b: P[index] for b, P in self.bodies.items()})

    def __len__(self) -> int:
        return len(self.t)


MAX_DEMO_FILE_BYTES = 64 * 1024 * 1024  # a demonstration's CSV: 100,000 rows are about 9 MB
MAX_DEMO_ROWS = 100_000  # over 16 minutes at 100 Hz (as the wire contract's demonstrations)


def _rows(name: str, reader: Any, quat_tolerance: float) -> tuple[list[list[float]], list[str]]:
    """The rows' values of ``COLUMNS`` (and of ``GRIPPER_COLUMNS`` and the bodies'
    where the header has them), validated, and those columns' names."""
    cols, width, names = _columns(name, next(reader, None))
    rows: list[list[float]] = []
    for k, rec in enumerate(reader, start=1):
        if not rec or all(not x.strip() for x in rec):
            continue
        if len(rows) >= MAX_DEMO_ROWS:
            raise DemoError(name, k, f"more than {MAX_DEMO_ROWS} rows")
        vals = _row(name, k, rec, cols, names, width, quat_tolerance)
        if rows and vals[0] <= rows[-1][0]:
            raise DemoError(name, k, f"time {vals[0]} does not increase "
                            f"(previous row has {rows[-1][0]})")
        rows.append(vals)
    return rows, names


def read_demo_csv(path: str | Path, min_samples: int = MIN_SAMPLES,
                  quat_tolerance: float = QUAT_TOLERANCE) -> Demo:
    """Read and validate one demonstration CSV.

    Rows are counted from 1 for the first data row (the header is line 1, so row N
    is line N + 1).

    Raises
    ------
    DemoError
        Missing columns, a non-numeric or non-finite value, a quaternion whose norm is
        off 1 by more than ``quat_tolerance``, times not strictly increasing, or fewer
        than ``min_samples`` rows.
    """
    path = Path(path)
    name = str(path)
    try:
        raw = open_regular(path, MAX_DEMO_FILE_BYTES, name)
    except FileError as exc:
        raise DemoError(name, None, exc.problem) from None
    with io.TextIOWrapper(raw, encoding="utf-8", errors="strict", newline="") as fh:
        try:
            rows, names = _rows(name, csv.reader(fh), quat_tolerance)
        except UnicodeDecodeError as exc:
            raise DemoError(name, None, f"not UTF-8 text (byte {exc.start} of a block)") from None
        except csv.Error as exc:
            raise DemoError(name, None, f"not a CSV file ({exc})") from None
    if len(rows) < min_samples:
        raise DemoError(name, len(rows) or None,
                        f"too few samples: {len(rows)} rows, need at least {min_samples}")
    a = np.array(rows)
    poses = np.concatenate([a[:, 1:4], se3.quaternion_normalize(a[:, 4:8])], axis=1)
    grip = len(names) > len(COLUMNS) and names[len(COLUMNS)] == GRIPPER_COLUMNS[0]
    start = len(COLUMNS) + (len(GRIPPER_COLUMNS) if grip else 0)
    bodies = {}
    for i in range(start, len(names), len(DEMO_BODY_FIELDS)):
        q = se3.quaternion_normalize(a[:, i + 3:i + 7])
        bodies[names[i].rsplit(".", 1)[0]] = np.concatenate([a[:, i:i + 3], q * np.where(
            q[:, 3:] < 0.0, -1.0, 1.0)], axis=1)
    return Demo(name=path.name, t=a[:, 0], poses=poses, width=a[:, 8] if grip else None,
                grasped=a[:, 9] == 1.0 if grip else None, bodies=bodies)


def _columns(name: str, header: list[str] | None) -> tuple[list[int], int, list[str]]:
    """Index of each of ``COLUMNS`` in the header (and of ``GRIPPER_COLUMNS`` after them,
    where it has both, and of the bodies' columns after those), the header's width and
    the names of the columns indexed."""
    if header is None:
        raise DemoError(name, None, f"empty file (expected the header {','.join(COLUMNS)})")
    header = [h.strip() for h in header]
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise DemoError(name, None, f"missing column(s) {', '.join(missing)} "
                        f"(header must contain {','.join(COLUMNS)})")
    grip = [c for c in GRIPPER_COLUMNS if c in header]
    if grip and len(grip) < len(GRIPPER_COLUMNS):
        lacking = next(c for c in GRIPPER_COLUMNS if c not in grip)
        raise DemoError(name, None, f"column {grip[0]} without column {lacking} (the gripper's "
                        f"columns {','.join(GRIPPER_COLUMNS)} come both or neither)")
    names = list(COLUMNS) + grip + _body_columns(name, header)
    return [header.index(c) for c in names], len(header), names


def _body_columns(name: str, header: list[str]) -> list[str]:
    """The bodies' columns of a header, seven per body (``<body>.x`` ... ``<body>.qw``),
    bodies in the order of their first column: a column ``<name>.<x|y|z|qx|qy|qz|qw>``
    is a body's, and a body's columns come all seven or none."""
    bodies: list[str] = []
    for h in header:
        body, _, part = h.rpartition(".")
        if body and part in DEMO_BODY_FIELDS and body not in bodies:
            bodies.append(body)
    if len(bodies) > MAX_DEMO_BODIES:
        raise DemoError(name, None, f"{len(bodies)} bodies' columns, at most {MAX_DEMO_BODIES}")
    out: list[str] = []
    for body in bodies:
        problem = name_problem(body)
        if problem:
            raise DemoError(name, None, f"column {body}.{DEMO_BODY_FIELDS[0]}: not a body's name: {problem}")
        cols = [f"{body}.{c}" for c in DEMO_BODY_FIELDS]
        lacking = [c for c in cols if c not in header]
        if lacking:
            raise DemoError(name, None, f"body {body}: missing column(s) {', '.join(lacking)} (a "
                            f"body's pose is all of {','.join(cols)})")
        out += cols
    return out


def _row(name: str, k: int, rec: list[str], cols: list[int], names: list[str], width: int,
         quat_tolerance: float) -> list[float]:
    """The values of ``names`` (at ``cols``) in data row ``k``: finite numbers, unit
    quaternions (the hand's and each body's), a width in [0, MAX_GRIPPER_WIDTH] m,
    grasped 0 or 1."""
    if len(rec) < width:
        raise DemoError(name, k, f"expected {width} values, got {len(rec)}")
    vals = []
    for c, j in zip(names, cols, strict=True):
        s = rec[j].strip()
        try:
            v = float(s)
        except ValueError:
            raise DemoError(name, k, f"column {c}: not a number: {s!r}") from None
        if not math.isfinite(v):
            raise DemoError(name, k, f"column {c}: not finite ({s})")
        vals.append(v)
    qn = math.sqrt(sum(x * x for x in vals[4:8]))
    if abs(qn - 1.0) > quat_tolerance:
        raise DemoError(name, k, f"quaternion (qx, qy, qz, qw) has norm {qn:.6f}, "
                        f"not unit (tolerance {quat_tolerance})")
    for i, c in enumerate(names):
        if c.endswith(".qx"):
            qn = math.sqrt(sum(x * x for x in vals[i:i + 4]))
            if abs(qn - 1.0) > quat_tolerance:
                body = c[:-3]
                raise DemoError(name, k, f"columns {body}.qx..{body}.qw: quaternion has norm {qn:.6f}, "
                                f"not unit (tolerance {quat_tolerance})")
    if len(names) > len(COLUMNS) and names[len(COLUMNS)] == GRIPPER_COLUMNS[0]:
        if not 0.0 <= vals[8] <= MAX_GRIPPER_WIDTH:
            raise DemoError(name, k, f"column gripper: width {vals[8]:g} m not in "
                            f"[0, {MAX_GRIPPER_WIDTH:g}]")
        if vals[9] not in (0.0, 1.0):
            raise DemoError(name, k, f"column grasped: {rec[cols[9]].strip()!r} is not 0 or 1")
    return vals


def read_demos(directory: str | Path, min_samples: int = MIN_SAMPLES,
               pattern: str = "*.csv") -> list[Demo]:
    """Read every ``*.csv`` in ``directory`` (sorted by name); all or nothing.

    Raises
    ------
    DemoError
        The first malformed file (see :func:`read_demo_csv`), or no CSV files.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise DemoError(str(directory), None, "not a directory")
    files = sorted(directory.glob(pattern))
    if not files:
        raise DemoError(str(directory), None, f"no demonstration files ({pattern})")
    return [read_demo_csv(f, min_samples=min_samples) for f in files]


# --- distances ------------------------------------------------------------------------


def tf_distance(poses_a: ArrayLike, poses_b: ArrayLike, alpha: float = 0.4) -> Array:
    """tf-norm (eq. 4.9) of the relative pose between poses, broadcasting (..., 7).

    ``||t_a - t_b|| + alpha * angle(q_a, q_b)``.
    """
    a = np.asarray(poses_a, dtype=float)
    b = np.asarray(poses_b, dtype=float)
    return (np.linalg.norm(a[..., :3] - b[..., :3], axis=-1)
            + alpha * _quaternion_angle(a[..., 3:], b[..., 3:]))


def _quaternion_angle(qa: Array, qb: Array) -> Array:
    """Rotation angle between unit quaternions, accurate near zero (unlike arccos):
    the 4-vectors are phi = 2 atan2(|a - b|, |a + b|) apart, the rotation 2 phi."""
    dm = np.linalg.norm(qa - qb, axis=-1)
    dp = np.linalg.norm(qa + qb, axis=-1)
    return 4.0 * np.arctan2(np.minimum(dm, dp), np.maximum(dm, dp))


# --- preprocessing --------------------------------------------------------------------


def spike_mask(poses: ArrayLike, half_window: int = 3, n_sigma: float = 5.0,
               min_jump: float = 0.005, min_angle: float = 0.05) -> NDArray[np.bool_]:
    """Hampel filter: True for samples that are *not* isolated gross outliers.

    A sample is an outlier when its position is farther than
    ``max(n_sigma * 1.4826 * MAD, min_jump)`` from the component-wise median of the
    ``2 * half_window + 1`` samples around it, or its orientation more than
    ``max(n_sigma * MAD, min_angle)`` rad from their (sign-aligned, normalised) median.

    Parameters
    ----------
    poses : array-like, shape (n, 7)

    Returns
    -------
    ndarray, shape (n,) of bool
    """
    P = np.asarray(poses, dtype=float)
    n = len(P)
    if n < 2 * half_window + 1:
        return np.ones(n, dtype=bool)
    w = 2 * half_window + 1
    pos = np.pad(P[:, :3], ((half_window, half_window), (0, 0)), mode="reflect")
    med = np.median(sliding_window_view(pos, w, axis=0), axis=-1)
    r = np.linalg.norm(P[:, :3] - med, axis=1)
    mad = np.median(np.abs(r - np.median(r)))
    bad = r > max(n_sigma * 1.4826 * mad, min_jump)
    q = P[:, 3:].copy()
    q *= np.where(np.sum(q * q[0], axis=1) < 0, -1.0, 1.0)[:, None]
    qp = np.pad(q, ((half_window, half_window), (0, 0)), mode="reflect")
    qm = np.median(sliding_window_view(qp, w, axis=0), axis=-1)
    qm /= np.maximum(np.linalg.norm(qm, axis=1, keepdims=True), 1e-12)
    ang = se3.quaternion_angle(q, qm)
    amad = np.median(np.abs(ang - np.median(ang)))
    bad |= ang > max(n_sigma * 1.4826 * amad, min_angle)
    return ~bad


def smooth_poses(poses: ArrayLike, window: int = 5) -> Array:
    """Moving average over ``window`` samples: positions component-wise, orientations as
    the normalised mean of sign-aligned quaternions (accurate for small windows).

    Parameters
    ----------
    poses : array-like, shape (n, 7)

    Returns
    -------
    ndarray, shape (n, 7)
    """
    P = np.array(poses, dtype=float)
    if window <= 1 or len(P) < 3:
        return P
    P[:, :3] = uniform_filter1d(P[:, :3], window, axis=0, mode="nearest")
    q = P[:, 3:]
    # Align each quaternion's sign with its predecessor before averaging.
    flips = np.sum(q[1:] * q[:-1], axis=1) < 0
    sign = np.concatenate([[1.0], np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)])
    q = uniform_filter1d(q * sign[:, None], window, axis=0, mode="nearest")
    P[:, 3:] = se3.quaternion_normalize(q)
    return P


def subsample_by_distance(poses: ArrayLike, spacing: float, alpha: float = 0.4,
                          translation_only: bool = False) -> NDArray[np.int64]:
    """Indices of samples kept at least ``spacing`` apart (Ch. 4.1.1).

    Greedy: starting at sample 0, keep the first sample whose tf-norm distance (eq. 4.9;
    the Euclidean distance when ``translation_only``) from the last kept one reaches
    ``spacing``. The last sample is kept too when it is at least ``spacing / 2`` away.

    Parameters
    ----------
    poses : array-like, shape (n, 7)
    spacing : float
        Metres (tf-norm with ``alpha`` metres per radian).

    Returns
    -------
    ndarray, shape (k,) of int, increasing
    """
    P = np.asarray(poses, dtype=float)
    a = 0.0 if translation_only else alpha
    keep = [0]
    i = 0
    n = len(P)
    chunk = 64
    while i < n - 1:
        j0 = i + 1
        found = -1
        while j0 < n:
            j1 = min(n, j0 + chunk)
            d = tf_distance(P[j0:j1], P[i], a)
            hit = np.flatnonzero(d >= spacing)
            if len(hit):
                found = j0 + int(hit[0])
                break
            j0 = j1
        if found < 0:
            if float(tf_distance(P[-1], P[i], a)) >= 0.5 * spacing and keep[-1] != n - 1:
                keep.append(n - 1)
            break
        keep.append(found)
        i = found
    return np.asarray(keep, dtype=np.int64)


# --- DTW ------------------------------------------------------------------------------


def dtw(a: ArrayLike, b: ArrayLike, alpha: float = 0.4) -> tuple[float, NDArray[np.int64]]:
    """Dynamic time warping of two pose sequences with the tf-norm (Ch. 5.1).

    The local cost of matching ``a[i]`` with ``b[j]`` is the tf-norm of their relative
    pose (eq. 4.9); the DTW cost is the sum of local costs along the optimal monotone
    path (steps (1, 0), (0, 1), (1, 1)). The table is filled one anti-diagonal at a
    time, vectorised.

    Parameters
    ----------
    a : array-like, shape (n, 7)
    b : array-like, shape (m, 7)
    alpha : float
        Metres per radian in the tf-norm.

    Returns
    -------
    cost : float
    path : ndarray, shape (k, 2) of int
        Matched index pairs (i, j), from (0, 0) to (n - 1, m - 1).
    """
    A = np.asarray(a, dtype=float)
    B = np.asarray(b, dtype=float)
    if A.ndim == 3:
        A = se3.pose_from_transform(A)
    if B.ndim == 3:
        B = se3.pose_from_transform(B)
    n, m = len(A), len(B)
    if n == 0 or m == 0:
        raise ValueError("dtw needs two non-empty sequences")
    C = tf_distance(A[:, None, :], B[None, :, :], alpha)
    D = np.full((n + 1, m + 1), np.inf)
    D[0, 0] = 0.0
    for k in range(2, n + m + 1):
        ii = np.arange(max(1, k - m), min(n, k - 1) + 1)
        jj = k - ii
        D[ii, jj] = C[ii - 1, jj - 1] + np.minimum(np.minimum(D[ii - 1, jj - 1], D[ii - 1, jj]),
                                                   D[ii, jj - 1])
    path = [(n - 1, m - 1)]
    i, j = n, m
    while i > 1 or j > 1:
        steps = ((i - 1, j - 1), (i - 1, j), (i, j - 1))
        i, j = min(steps, key=lambda s: D[s])
        path.append((i - 1, j - 1))
    return float(D[n, m]), np.asarray(path[::-1], dtype=np.int64)
