"""``sctd record``: record one demonstration from ``state`` and a task object's pose.

Samples, at a fixed rate, the newest ``sctd/<robot>/state`` and
``sctd/<robot>/objects/<object>`` and writes the end-effector pose in the object's
frame, ``T_obj_ee = T_world_obj^-1 T_world_ee``, as the learner's CSV
(``t,x,y,z,qx,qy,qz,qw``, see :mod:`sctd.learn.demos`), ``t`` from 0 on the state's
own clock (its ``stamp``), strictly increasing (a sample whose state has not advanced
is skipped), quaternions unit and in the ``qw >= 0`` hemisphere.

Files: the rows go to a hidden ``.demo-*.part`` file in the output folder, flushed as
they are written; on exit (``--duration`` elapsed, SIGINT or SIGTERM) it is synced and
linked to the next free ``demo_NNN.csv`` (``os.link`` fails rather than overwrite, so
two recorders never clobber each other), so a demonstration file only ever appears
complete. A recording shorter than the learner's minimum (10 rows) is discarded.

The finished demonstration is also published on ``sctd/<robot>/demos/<task>/<name>``
(:func:`sctd.runtime.codec.encode_demo`: the same rows as the file, ``name`` its stem,
``task`` from ``--task``, else the scene the simulator announces, else the object), so a
learner on another host gets it.

Works against any robot that speaks the wire contract; with ``sctd sim`` the object
defaults to the scene's task object (``task_object`` on the scene key).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import TextIO

import zenoh

from sctd import se3
from sctd.runtime import codec
from sctd.runtime.codec import DEFAULT_ROBOT
from sctd.runtime.timing import Ticker
from sctd.runtime.zsession import add_zenoh_arguments, session_from_args

COLUMNS = ",".join(codec.DEMO_COLUMNS)  # the CSV header: the learner's columns (sctd.learn.demos)
MIN_ROWS = codec.MIN_DEMO_ROWS  # sctd.learn.demos.MIN_SAMPLES: the learner refuses shorter ones
# s the session stays open after the demonstration is put, so that it leaves this
# process before the session closes (Zenoh may drop what is still queued then)
LINGER = 0.3


def row_from_poses(t: float, pose_world_ee: list[float], pose_world_obj: list[float]) -> list[float]:
    """``[t, x, y, z, qx, qy, qz, qw]`` of the ee in the object frame (qw >= 0)."""
    T = se3.invert_transform(se3.transform_from_pose(pose_world_obj)) @ se3.transform_from_pose(pose_world_ee)
    p = se3.pose_from_flat(se3.flat_from_transform(T))
    n = math.sqrt(sum(x * x for x in p[3:]))
    s = (1.0 if p[6] >= 0.0 else -1.0) / n
    return [t, p[0], p[1], p[2], p[3] * s, p[4] * s, p[5] * s, p[6] * s]


def format_row(row: list[float]) -> str:
    """One CSV line (time to the microsecond, poses to 1e-9)."""
    return f"{row[0]:.6f}," + ",".join(f"{x:.9f}" for x in row[1:]) + "\n"


def publish_final(tmp: Path, out_dir: Path, prefix: str = "demo_") -> Path:
    """Link ``tmp`` to the first free ``<prefix>NNN.csv`` in ``out_dir``; remove ``tmp``."""
    k = 0
    while True:
        final = out_dir / f"{prefix}{k:03d}.csv"
        try:
            os.link(tmp, final)
        except FileExistsError:
            k += 1
            continue
        tmp.unlink()
        return final


class Recorder:
    """Newest state and object pose from Zenoh, sampled into CSV rows.

    A context manager: subscribed while entered (``with Recorder(...) as rec:``).

    Parameters
    ----------
    session : zenoh.Session
    robot : str
    object_name : str or None
        None: take the ``task_object`` announced on the scene key.
    """

    def __init__(self, session: zenoh.Session, robot: str, object_name: str | None) -> None:
        self.session = session
        self.keys = codec.Keys(robot)
        self.object_name = object_name
        self.state: codec.StateMsg | None = None
        self.objects: dict[str, list[float]] = {}
        self.task: str | None = None  # the scene's name (pour, drawer), as the sim announces it
        self.dropped = 0
        self._subs = contextlib.ExitStack()  # the subscribers, while entered

    def __enter__(self) -> Recorder:
        """Subscribe (a failure midway undeclares the ones made); :meth:`__exit__`
        undeclares."""
        with contextlib.ExitStack() as stack:
            declare = self.session.declare_subscriber
            stack.enter_context(declare(self.keys.state, self._on_state))
            stack.enter_context(declare(self.keys.objects(), self._on_object))
            stack.enter_context(declare(self.keys.scene, self._on_scene))
            self._subs = stack.pop_all()
        return self

    def __exit__(self, *exc: object) -> None:
        self._subs.close()

    def _on_state(self, sample: zenoh.Sample) -> None:
        try:
            self.state = codec.decode_state(sample.payload.to_bytes())
        except codec.DecodeError:
            self.dropped += 1

    def _on_object(self, sample: zenoh.Sample) -> None:
        name = str(sample.key_expr).rsplit("/", 1)[-1]
        try:
            self.objects[name] = codec.decode_object(sample.payload.to_bytes()).pose
        except codec.DecodeError:
            self.dropped += 1

    def _on_scene(self, sample: zenoh.Sample) -> None:
        try:
            msg = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        task = msg.get("scene")
        if isinstance(task, str) and task:
            self.task = task
        name = msg.get("task_object")
        if self.object_name is None and isinstance(name, str) and name:
            self.object_name = name

    def sample(self) -> tuple[float, list[float], list[float]] | None:
        """(state stamp, ee pose, object pose), or None until both have arrived."""
        st = self.state
        obj = self.objects.get(self.object_name) if self.object_name else None
        if st is None or obj is None:
            return None
        return st.stamp, st.pose, obj


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the recorder's flags (``sctd record``, ``python -m sctd_services.record``) to
    ``p``."""
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder of demonstrations; writes the next free demo_NNN.csv")
    p.add_argument("--object", default=None, metavar="NAME",
                   help="task object whose frame the trajectory is expressed in "
                        "(default: the task object the simulator announces on the scene key)")
    p.add_argument("--task", default=None, metavar="NAME",
                   help="the task the demonstration is published under, sctd/<robot>/demos/<task>/<name> "
                        "(default: the scene the simulator announces, else the object's name)")
    p.add_argument("--robot", default=DEFAULT_ROBOT, help="key prefix sctd/<robot> (default %(default)s)")
    p.add_argument("--rate", type=float, default=100.0, help="sampling rate, Hz (default %(default)s)")
    p.add_argument("--min-distance", type=float, default=0.0, metavar="M",
                   help="skip samples closer than this (m, ee position) to the last row (default 0)")
    p.add_argument("--duration", type=float, default=None,
                   help="record this many seconds (default: until SIGINT/SIGTERM)")
    p.add_argument("--wait", type=float, default=10.0,
                   help="give up when no state/object arrives within this many seconds (default %(default)s)")
    add_zenoh_arguments(p)


def run(args: argparse.Namespace) -> int:
    """``sctd record`` with parsed arguments (:func:`add_arguments`); returns the exit
    code (1: nothing recorded, 2: bad flags)."""
    if args.rate <= 0 or args.min_distance < 0 or (args.duration is not None and args.duration <= 0):
        print("sctd record: --rate, --duration: must be > 0; --min-distance: must be >= 0",
              file=sys.stderr)
        return 2
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    with session_from_args(args) as session, Recorder(session, args.robot, args.object) as rec:
        if not _wait_for_first_sample(rec, args.wait, stop):
            return 1
        print(f"sctd record: recording the ee in the frame of {rec.object_name!r} at "
              f"{args.rate:g} Hz{' until SIGINT' if args.duration is None else ''}",
              file=sys.stderr, flush=True)
        rows: list[list[float]] = []
        final = _record_file(rec, out_dir, args, stop, rows)
        if final is None:
            return 1
        _publish(session, rec, args.task, final.stem, rows)
    print(f"sctd record: {len(rows)} rows -> {final}", file=sys.stderr, flush=True)
    print(final, flush=True)
    return 0


def _record_file(rec: Recorder, out_dir: Path, args: argparse.Namespace, stop: threading.Event,
                 rows: list[list[float]]) -> Path | None:
    """Record into a hidden part file, then link it to the next free ``demo_NNN.csv``
    (None, and the part file removed, when it is too short for the learner)."""
    fd, name = _mkstemp(out_dir)
    tmp = Path(name)
    try:
        with os.fdopen(fd, "w", newline="") as fh:
            _record_rows(rec, fh, args, stop, rows)
            fh.flush()
            os.fsync(fh.fileno())
        if len(rows) >= MIN_ROWS:
            return publish_final(tmp, out_dir)
    finally:
        tmp.unlink(missing_ok=True)  # linked to its final name, or not to be kept
    print(f"sctd record: only {len(rows)} rows (the learner needs {MIN_ROWS}); nothing written",
          file=sys.stderr)
    return None


def _publish(session: zenoh.Session, rec: Recorder, task: str | None, name: str,
             rows: list[list[float]]) -> None:
    """The finished demonstration on ``sctd/<robot>/demos/<task>/<name>`` (a learner on
    another host stores it); ``task``: the flag, else the scene's, else the object."""
    assert rec.object_name is not None
    task = task or rec.task or rec.object_name
    key = rec.keys.demos(task, name)
    session.put(key, codec.encode_demo(task, name, rec.object_name, rows),
                congestion_control=zenoh.CongestionControl.BLOCK)
    print(f"sctd record: published {key}", file=sys.stderr, flush=True)
    time.sleep(LINGER)


def _wait_for_first_sample(rec: Recorder, wait: float, stop: threading.Event) -> bool:
    """Wait until both the state and the object arrived; False (said on stderr when it
    timed out) if ``wait`` s passed or ``stop`` was set first."""
    give_up = time.monotonic() + wait
    while not stop.is_set() and rec.sample() is None:
        if time.monotonic() > give_up:
            what = "state" if rec.state is None else f"object {rec.object_name or '(task object)'}"
            print(f"sctd record: no {what} within {wait:g} s", file=sys.stderr)
            return False
        time.sleep(0.01)
    return not stop.is_set()


def _record_rows(rec: Recorder, fh: TextIO, args: argparse.Namespace, stop: threading.Event,
                 out: list[list[float]]) -> None:
    """Write the header and one row per tick at ``--rate`` until ``stop`` or
    ``--duration``, skipping samples whose state has not advanced or that lie closer
    than ``--min-distance`` to the last row; each row written is appended to ``out``."""
    fh.write(COLUMNS + "\n")
    ticker = Ticker(1.0 / args.rate, spin=0.0)
    end = None if args.duration is None else time.monotonic() + args.duration
    t0 = last_t = None
    last_p = None
    while not stop.is_set():
        now, _ = ticker.wait()
        if end is not None and now >= end:
            break
        s = rec.sample()
        if s is None:
            continue
        stamp, pose_ee, pose_obj = s
        if t0 is None:
            t0 = stamp
        t = stamp - t0
        if last_t is not None and t <= last_t:
            continue  # the state has not advanced since the last row
        row = row_from_poses(t, pose_ee, pose_obj)
        if last_p is not None and args.min_distance > 0 and math.dist(row[1:4], last_p) < args.min_distance:
            continue
        line = format_row(row)
        fh.write(line)
        fh.flush()
        out.append([float(x) for x in line.split(",")])  # as written: the file and the message agree
        last_t, last_p = t, row[1:4]


def _mkstemp(out_dir: Path) -> tuple[int, str]:
    import tempfile

    fd, name = tempfile.mkstemp(prefix=".demo-", suffix=".part", dir=out_dir, text=True)
    umask = os.umask(0)
    os.umask(umask)
    os.fchmod(fd, 0o666 & ~umask)  # mkstemp's 0600 would stick to the final file
    return fd, name


def main(argv: list[str] | None = None) -> int:
    """``python -m sctd_services.record``: parse the flags (the same as ``sctd record``)
    and record."""
    p = argparse.ArgumentParser(prog="sctd-record", description=__doc__.split("\n\n")[0])
    add_arguments(p)
    return run(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
