"""``sctd record``: record one demonstration from ``state`` and a task object's pose.

Samples, at a fixed rate, the newest ``sctd/<robot>/state`` and
``sctd/<robot>/objects/<object>`` and writes the end-effector pose in the object's
frame, ``T_obj_ee = T_world_obj^-1 T_world_ee``, as the learner's CSV
(``t,x,y,z,qx,qy,qz,qw``, see :mod:`sctd.learn.demos`), ``t`` from 0 on the state's
own clock (its ``stamp``), strictly increasing (a sample whose state has not advanced
is skipped), quaternions unit and in the ``qw >= 0`` hemisphere. Where the first sampled
state carries a gripper reading, every row also has the fingers' ``gripper`` width (m)
and ``grasped`` (0/1) (``t,x,y,z,qx,qy,qz,qw,gripper,grasped``; a later state without a
reading repeats the last one); otherwise the file is exactly the pose's columns. Every
other body whose pose is known at the first row (``objects/<name>`` but the task
object's; with ``--bodies``, those named, the first row waiting for them) adds seven
columns, its pose in the task object's frame (``<body>.x, ..., <body>.qw``,
:mod:`sctd.learn.demos`): the learner chooses each state's frame among them.

Files: the rows go to a hidden ``.demo-*.part`` file in the output folder, flushed as
they are written; on exit (``--duration`` elapsed, SIGINT or SIGTERM) it is synced and
linked to the next free ``demo_NNN.csv`` (``os.link`` fails rather than overwrite, so
two recorders never clobber each other), so a demonstration file only ever appears
complete. A recording shorter than the learner's minimum (10 rows) is discarded.

The finished demonstration is also published on ``sctd/<robot>/demos/<task>/<name>``
(:func:`sctd.wire.codec.encode_demo`: the same rows as the file, ``name`` its stem,
``task`` from ``--task``, else the scene the simulator announces, else the object), so a
learner on another host gets it.

Works against any robot that speaks the wire contract; with ``sctd sim`` the object
defaults to the scene's task object (``task_object`` on the scene key).

As a library (``sctd teach`` records with it): a :class:`Recorder` holds the newest
state, object poses and scene message; each :class:`Take` on it is one demonstration,
started and stopped, then kept (the file and the message, as ``sctd record`` makes them)
or discarded (nothing written, nothing published).
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
from typing import Any, TextIO

import zenoh

from sctd import se3
from sctd.app.errors import fail
from sctd.app.options import add_robot_argument
from sctd.task.demos import DEMOS_FILE, DemosInfo, read_demos_info
from sctd.timing import Ticker
from sctd.wire import Keys, codec
from sctd.wire.session import MSGPACK, add_zenoh_arguments, session_from_args

COLUMNS = ",".join(codec.DEMO_COLUMNS)  # the CSV header: the learner's columns (sctd.learn.demos)
GRIPPER_COLUMNS = ",".join(codec.DEMO_COLUMNS + codec.DEMO_GRIPPER_COLUMNS)  # ... with the fingers
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


def format_row(row: list[float], bodies: tuple[str, ...] = ()) -> str:
    """One CSV line (time to the microsecond, poses to 1e-9; a row with the gripper's
    columns has the fingers' width to the micrometre and grasped as 0 or 1; then each of
    ``bodies``' poses; :func:`sctd.wire.codec.format_demo_row`)."""
    return codec.format_demo_row(row, codec.demo_columns([row], bodies)) + "\n"


def body_pose(pose_world_body: list[float], pose_world_obj: list[float]) -> list[float]:
    """A body's pose in the task object's frame (qw >= 0): a row's seven ``<body>.*``."""
    return row_from_poses(0.0, pose_world_body, pose_world_obj)[1:]


def gripper_values(reading: codec.GripperReading) -> list[float]:
    """A row's ``gripper`` and ``grasped`` from a state's gripper reading."""
    return [float(reading.width), 1.0 if reading.grasped else 0.0]


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
    task : str or None
        The task its demonstrations are published under; None: the scene the simulator
        announces (``pour``, ``drawer``), else the object's name.
    bodies : tuple of str or None
        The other bodies whose poses each row carries (in the object's frame); None:
        every body whose pose is known at the first row.
    """

    def __init__(self, session: zenoh.Session, robot: str, object_name: str | None,
                 task: str | None = None, bodies: tuple[str, ...] | None = None) -> None:
        self.session = session
        self.keys = Keys(robot)
        self.object_name = object_name
        self.bodies = bodies  # the other bodies recorded (None: all known at the first row)
        self.state: codec.StateMsg | None = None
        self.objects: dict[str, list[float]] = {}
        self._task = task
        self.scene_name: str | None = None  # as the simulator announces it (pour, drawer)
        self.scene: dict[str, Any] | None = None  # the newest scene message (outcome, health)
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
        self.scene = msg
        scene = msg.get("scene")
        if isinstance(scene, str) and scene:
            self.scene_name = scene
        name = msg.get("task_object")
        if self.object_name is None and isinstance(name, str) and name:
            self.object_name = name

    @property
    def task(self) -> str | None:
        """The task demonstrations are published under: the given one, else the scene's,
        else the object's name (None while neither is known)."""
        return self._task or self.scene_name or self.object_name

    def sample(self) -> tuple[float, list[float], list[float]] | None:
        """(state stamp, ee pose, object pose), or None until both have arrived."""
        s = self.sample_gripper()
        return None if s is None else s[:3]

    def sample_gripper(self) -> tuple[float, list[float], list[float], codec.GripperReading | None] | None:
        """:meth:`sample` and the same state's gripper reading (None: it has none)."""
        st = self.state
        obj = self.objects.get(self.object_name) if self.object_name else None
        if st is None or obj is None:
            return None
        return st.stamp, st.pose, obj, st.gripper

    def row_bodies(self) -> tuple[str, ...] | None:
        """The bodies a take's first row fixes: :attr:`bodies` when all are known (None
        while one is not), else every known body but the task object, sorted."""
        if self.bodies is not None:
            named = tuple(b for b in self.bodies if b != self.object_name)
            return named if all(b in self.objects for b in named) else None
        return tuple(sorted(n for n in self.objects if n != self.object_name))


class Take:
    """One demonstration being recorded, then kept or discarded.

    Rows sampled from a :class:`Recorder` go to a hidden ``.demo-*.part`` file in
    ``out_dir`` (flushed as they are written). :meth:`keep` syncs it, links it to the next
    free ``demo_NNN.csv`` and publishes it on ``sctd/<robot>/demos/<task>/<name>``;
    :meth:`discard` removes it and publishes nothing. A context manager: leaving it
    without :meth:`keep` (an error midway included) discards, so a demonstration file
    only ever appears complete::

        with Take(rec, out_dir) as take:
            take.start()            # sampled in a background thread
            ...                     # the demonstration
            take.stop()
            path = take.keep() if it_went_well else take.discard()

    (``sctd record`` calls :meth:`record` instead, which samples in the calling thread.)

    Parameters
    ----------
    rec : Recorder
        Entered (subscribed); its object must be known when sampling starts.
    out_dir : Path
        Folder of demonstrations (exists).
    rate : float
        Sampling rate, Hz.
    min_distance : float
        Skip samples closer than this (m, ee position) to the last row.
    Attributes
    ----------
    rows : list of list of float
        The rows as written (``t, x, y, z, qx, qy, qz, qw`` and, where the state has a
        gripper, ``gripper, grasped``, then seven per body), so the file and the message
        agree.
    bodies : tuple of str
        The bodies whose poses the rows carry (fixed by the first row).
    path : Path or None
        The kept file.
    key : str or None
        The key it was published on.
    """

    def __init__(self, rec: Recorder, out_dir: Path, rate: float = 100.0,
                 min_distance: float = 0.0) -> None:
        self.rec = rec
        self.out_dir = Path(out_dir)
        self.rate = rate
        self.min_distance = min_distance
        self.rows: list[list[float]] = []
        self.bodies: tuple[str, ...] = ()
        self.path: Path | None = None
        self.key: str | None = None
        self._fh: TextIO | None = None
        self._part: Path | None = None
        self._halt = threading.Event()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    def __enter__(self) -> Take:
        """Create the part file (its CSV header comes with the first row: its columns
        depend on whether the state has a gripper)."""
        fd, name = _mkstemp(self.out_dir)
        self._part = Path(name)
        try:
            self._fh = os.fdopen(fd, "w", newline="")
        except BaseException:
            self._part.unlink(missing_ok=True)
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        """Stop sampling; remove the part file unless it was kept."""
        self._halt.set()
        if self._thread is not None:
            self._thread.join()
        self.discard()

    def record(self, stop: threading.Event, duration: float | None = None) -> None:
        """Sample rows in this thread until ``stop`` is set or ``duration`` s passed."""
        assert self._fh is not None, "Take.record outside its with block"
        self.bodies = _record_rows(self.rec, self._fh, self.rate, self.min_distance, stop, duration,
                                   self.rows)

    def start(self) -> Take:
        """Sample rows in a background thread until :meth:`stop` (ValueError, before
        any row, when the folder holds another object's demonstrations)."""
        check_demos_folder(self.out_dir, self.rec.object_name)
        def sample() -> None:
            try:
                self.record(self._halt)
            except BaseException as e:  # handed to stop(), which raises it
                self._error = e

        self._thread = threading.Thread(target=sample, name="take", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> int:
        """End sampling (the background thread's error, if any, is raised here); the
        number of rows."""
        self._halt.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._error is not None:
            raise self._error
        return len(self.rows)

    @property
    def long_enough(self) -> bool:
        """Whether the learner accepts it (at least MIN_ROWS rows)."""
        return len(self.rows) >= MIN_ROWS

    def keep(self) -> Path | None:
        """Sync the file, link it to the next free ``demo_NNN.csv`` and publish it; None
        (and discarded) when it is too short for the learner."""
        self.stop()
        if not self.long_enough:
            self.discard()
            return None
        fh, part = self._fh, self._part
        assert fh is not None and part is not None, "Take.keep outside its with block"
        fh.flush()
        os.fsync(fh.fileno())
        fh.close()
        self.path = publish_final(part, self.out_dir)
        self._part = None
        assert self.rec.object_name is not None and self.rec.task is not None
        note_demos_folder(self.out_dir, DemosInfo(self.rec.task, self.rec.object_name))
        self._publish(self.path.stem)
        return self.path

    def discard(self) -> None:
        """Remove the part file (nothing is published); a kept take stays kept."""
        self._halt.set()
        if self._fh is not None and not self._fh.closed:
            self._fh.close()
        if self._part is not None:
            self._part.unlink(missing_ok=True)
            self._part = None

    def _publish(self, name: str) -> None:
        """The finished demonstration on ``sctd/<robot>/demos/<task>/<name>`` (a learner
        on another host stores it), under the recorder's task."""
        rec = self.rec
        task = rec.task
        assert rec.object_name is not None and task is not None
        self.key = rec.keys.demos(task, name)
        rec.session.put(self.key, codec.encode_demo(task, name, rec.object_name, self.rows, self.bodies),
                        congestion_control=zenoh.CongestionControl.BLOCK, encoding=MSGPACK)


def check_demos_folder(out_dir: Path, object_name: str | None) -> None:
    """ValueError when ``out_dir``'s ``demos.yaml`` says its demonstrations are in
    another object's frame than ``object_name``'s (a skill learned from the mix would be
    in neither)."""
    info = read_demos_info(out_dir)
    if info is not None and object_name is not None and info.object != object_name:
        raise ValueError(f"{out_dir / DEMOS_FILE}: the demonstrations here are of {info.object!r} "
                         f"(task {info.task}), not {object_name!r}: record into another folder")


def note_demos_folder(out_dir: Path, info: DemosInfo) -> None:
    """Write ``out_dir``'s ``demos.yaml`` unless it is there (never overwritten; two
    recorders racing write the same)."""
    path = out_dir / DEMOS_FILE
    if path.exists():
        return
    fd, name = _mkstemp(out_dir)
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(info.to_yaml())
        with contextlib.suppress(FileExistsError):
            os.link(name, path)
    finally:
        Path(name).unlink(missing_ok=True)


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
    add_robot_argument(p)
    p.add_argument("--bodies", default=None, metavar="NAME,...",
                   help="the other bodies whose poses each row carries, in the object's frame "
                        "(default: every body whose pose is known at the first row; '' for none)")
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
        return fail("record", "--rate, --duration: must be > 0; --min-distance: must be >= 0")
    bodies = None if args.bodies is None else tuple(b for b in args.bodies.split(",") if b)
    for b in bodies or ():
        problem = codec.name_problem(b) or ("the task object" if b == args.object else "")
        if problem:
            return fail("record", f"--bodies: {b!r}: {problem}")
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    with session_from_args(args) as session, Recorder(session, args.robot, args.object, args.task,
                                                            bodies) as rec:
        if not _wait_for_first_sample(rec, args.wait, stop):
            return 1
        try:
            check_demos_folder(out_dir, rec.object_name)
        except ValueError as e:
            return fail("record", str(e))
        print(f"sctd record: recording the ee in the frame of {rec.object_name!r} at "
              f"{args.rate:g} Hz{' until SIGINT' if args.duration is None else ''}",
              file=sys.stderr, flush=True)
        rows: list[list[float]] = []
        final, key = _record_file(rec, out_dir, args, stop, rows)
        if final is None:
            return 1
        print(f"sctd record: published {key}", file=sys.stderr, flush=True)
        time.sleep(LINGER)
    print(f"sctd record: {len(rows)} rows -> {final}", file=sys.stderr, flush=True)
    print(final, flush=True)
    return 0


def _record_file(rec: Recorder, out_dir: Path, args: argparse.Namespace, stop: threading.Event,
                 rows: list[list[float]]) -> tuple[Path | None, str | None]:
    """One take until ``stop`` or ``--duration``, kept (linked to the next free
    ``demo_NNN.csv`` and published) unless it is too short for the learner; (file, key),
    or (None, None) with the part file removed. The rows written are put in ``rows``."""
    with Take(rec, out_dir, args.rate, args.min_distance) as take:
        take.record(stop, args.duration)
        rows.extend(take.rows)
        if take.keep() is None:
            print(f"sctd record: only {len(rows)} rows (the learner needs {MIN_ROWS}); nothing written",
                  file=sys.stderr)
            return None, None
        return take.path, take.key


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


def _record_rows(rec: Recorder, fh: TextIO, rate: float, min_distance: float, stop: threading.Event,
                 duration: float | None, out: list[list[float]]) -> tuple[str, ...]:
    """One row per tick at ``rate`` Hz until ``stop`` or ``duration`` s, skipping samples
    whose state has not advanced or that lie closer than ``min_distance`` to the last
    row; each row written is appended to ``out`` (as written: the file and the message
    agree). The first row fixes the columns and writes the header: the gripper's too
    when its state has a gripper reading (then a state without one repeats the last),
    and the bodies' (:meth:`Recorder.row_bodies`, each at its newest pose); returns the
    bodies."""
    ticker = Ticker(1.0 / rate, spin=0.0)
    end = None if duration is None else time.monotonic() + duration
    t0 = last_t = None
    last_p = None
    grip: list[float] | None = None  # the newest gripper values, once the columns have them
    bodies: tuple[str, ...] = ()
    while not stop.is_set():
        now, _ = ticker.wait()
        if end is not None and now >= end:
            break
        s = rec.sample_gripper()
        if s is None:
            continue
        stamp, pose_ee, pose_obj, reading = s
        if t0 is None:
            t0 = stamp
        t = stamp - t0
        if last_t is not None and t <= last_t:
            continue  # the state has not advanced since the last row
        row = row_from_poses(t, pose_ee, pose_obj)
        if last_p is not None and min_distance > 0 and math.dist(row[1:4], last_p) < min_distance:
            continue
        if not out:  # the first row: the header, with the gripper's columns if it has a reading
            known = rec.row_bodies()
            if known is None:
                continue  # a body asked for has not been seen yet
            bodies = known
            grip = None if reading is None else gripper_values(reading)
            header = COLUMNS if grip is None else GRIPPER_COLUMNS
            fh.write(header + "".join("," + ",".join(codec.demo_body_columns(b)) for b in bodies) + "\n")
        if grip is not None:
            grip = gripper_values(reading) if reading is not None else grip
            row += grip
        for b in bodies:
            row += body_pose(rec.objects[b], pose_obj)
        line = format_row(row, bodies)
        fh.write(line)
        fh.flush()
        out.append([float(x) for x in line.split(",")])
        last_t, last_p = t, row[1:4]
    return bodies


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
