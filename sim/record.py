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

Works against any robot that speaks the wire contract; with ``sctd sim`` the object
defaults to the scene's task object (``task_object`` on the scene key).
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

import zenoh

from sctd import se3
from sctd.runtime import codec
from sctd.runtime.timing import Ticker
from sctd.runtime.zsession import session_from_args

COLUMNS = "t,x,y,z,qx,qy,qz,qw"
MIN_ROWS = 10  # sctd.learn.demos.MIN_SAMPLES: shorter files make the learner refuse the folder


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

    Parameters
    ----------
    session : zenoh.Session
    robot : str
    object_name : str or None
        None: take the ``task_object`` announced on the scene key.
    """

    def __init__(self, session: zenoh.Session, robot: str, object_name: str | None) -> None:
        self.keys = codec.Keys(robot)
        self.object_name = object_name
        self.state: codec.StateMsg | None = None
        self.objects: dict[str, list[float]] = {}
        self.dropped = 0
        self._subs = [
            session.declare_subscriber(self.keys.state, self._on_state),
            session.declare_subscriber(self.keys.objects(), self._on_object),
        ]
        if object_name is None:
            self._subs.append(session.declare_subscriber(self.keys.scene, self._on_scene))

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
        if self.object_name is not None:
            return
        try:
            msg = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        name = msg.get("task_object")
        if isinstance(name, str) and name:
            self.object_name = name

    def sample(self) -> tuple[float, list[float], list[float]] | None:
        """(state stamp, ee pose, object pose), or None until both have arrived."""
        st = self.state
        obj = self.objects.get(self.object_name) if self.object_name else None
        if st is None or obj is None:
            return None
        return st.stamp, st.pose, obj

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()


def run(args: argparse.Namespace) -> int:
    """``sctd record`` with parsed arguments; returns the exit code."""
    if args.rate <= 0 or args.min_distance < 0 or (args.duration is not None and args.duration <= 0):
        print("sctd record: --rate and --duration must be positive, --min-distance >= 0",
              file=sys.stderr)
        return 2
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    rows = 0
    tmp: Path | None = None
    with session_from_args(args) as session:
        rec = Recorder(session, args.robot, args.object)
        try:
            give_up = time.monotonic() + args.wait
            while not stop.is_set() and rec.sample() is None:
                if time.monotonic() > give_up:
                    what = "state" if rec.state is None else f"object {rec.object_name or '(task object)'}"
                    print(f"sctd record: no {what} within {args.wait:g} s", file=sys.stderr)
                    return 1
                time.sleep(0.01)
            if stop.is_set():
                return 1
            print(f"sctd record: recording the ee in the frame of {rec.object_name!r} at "
                  f"{args.rate:g} Hz{' until SIGINT' if args.duration is None else ''}",
                  file=sys.stderr, flush=True)
            fd, name = _mkstemp(out_dir)
            tmp = Path(name)
            with os.fdopen(fd, "w", newline="") as fh:
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
                    if last_p is not None and args.min_distance > 0 and math.dist(
                            row[1:4], last_p) < args.min_distance:
                        continue
                    fh.write(format_row(row))
                    fh.flush()
                    rows += 1
                    last_t, last_p = t, row[1:4]
                fh.flush()
                os.fsync(fh.fileno())
        finally:
            rec.close()
    assert tmp is not None
    if rows < MIN_ROWS:
        tmp.unlink()
        print(f"sctd record: only {rows} rows (the learner needs {MIN_ROWS}); nothing written",
              file=sys.stderr)
        return 1
    final = publish_final(tmp, out_dir)
    print(f"sctd record: {rows} rows -> {final}", file=sys.stderr, flush=True)
    print(final, flush=True)
    return 0


def _mkstemp(out_dir: Path) -> tuple[int, str]:
    import tempfile

    fd, name = tempfile.mkstemp(prefix=".demo-", suffix=".part", dir=out_dir, text=True)
    umask = os.umask(0)
    os.umask(umask)
    os.fchmod(fd, 0o666 & ~umask)  # mkstemp's 0600 would stick to the final file
    return fd, name


def main(argv: list[str] | None = None) -> int:
    from sctd.cli.sim import add_record_arguments

    p = argparse.ArgumentParser(prog="sctd-record", description=__doc__.split("\n\n")[0])
    add_record_arguments(p)
    return run(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
