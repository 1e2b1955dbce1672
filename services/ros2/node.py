"""``sctd ros``: a ROS 2 node (rclpy, Fast DDS) that lets a ROS 2 arm be sctd's robot,
perception its object source and a ROS joystick its input (``docs/ros2.md``).

It is a bridge process of its own beside ``sctd run``: a Zenoh session on sctd's keys
and an rclpy node on ROS 2 topics, with the rules of :class:`~.bridge.Bridge` between
them. rclpy's callbacks run on this process's main thread (the executor), sctd's
messages to ROS on a thread of the node's own; the bridge locks around each message.
Nothing here runs on the daemon's tick.

sctd -> ROS runs on a thread of its own (:class:`_Outbound`): the daemon puts a target
every millisecond, and a Python callback for each cost the node more than everything
else it does; instead the target and the status wait in Zenoh ring channels (the
newest target; the statuses in order) and the thread takes them at the target rate, on
absolute deadlines, with the bridge's watch and the skill's markers on the same
wake-ups. When the person's Joy begins a push while the target rests, the thread takes
each target as it arrives until the first that moved has gone out (at once, by the
bridge's rule), then returns to the schedule.

Topics (names, frame and QoS are flags): in, the hand's ``PoseStamped``
(``--pose-topic``) or ``JointState`` (``--joint-states-topic`` with ``--urdf`` and
``--ee-frame``), one ``PoseStamped`` per object (``--object NAME=TOPIC``), ``Joy``
(``--joy-topic``); out, the target as ``PoseStamped`` (``--target-topic``) and, with
``--twist-topic``, ``TwistStamped``, status as ``DiagnosticArray``. Subscriptions are
best effort, keep last 1 (they match reliable and best-effort publishers; the newest
wins); the command topics are reliable, keep last 1 by default (``--qos-depth``,
``--qos-reliability``).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from sctd.app.errors import EXIT_OK, EXIT_USAGE, fail
from sctd.app.options import add_robot_argument
from sctd.wire import Keys
from sctd.wire.session import add_zenoh_arguments, session_from_args

from .bridge import MARKERS_PERIOD, Bridge, BridgeOptions, ros_messages

ZENOH_RUNTIME = "(rx: (worker_threads: 1))"  # the node's Zenoh runtime (see run)

log = logging.getLogger("sctd.ros")
WATCH_RATE = 50.0  # Hz, at least, of the outbound thread's wake-ups (targets that stopped: a zero twist)
POLL = 2e-4  # s between looks at the target ring while a push is about to move the target


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = ("A ROS 2 node (rclpy) between a ROS 2 arm, its perception and joystick and sctd's "
                     "keys: the hand's pose or joint states, objects' poses and Joy in; the target "
                     "(PoseStamped, optionally TwistStamped) and diagnostics out (docs/ros2.md).")
    add_robot_argument(p)
    p.add_argument("--world-frame", default="world", metavar="FRAME",
                   help="the frame every pose is in (a message in another frame is dropped and counted: "
                        "there is no tf2 here)")
    hand = p.add_mutually_exclusive_group()
    hand.add_argument("--pose-topic", metavar="TOPIC", help="the hand's geometry_msgs/PoseStamped")
    hand.add_argument("--joint-states-topic", metavar="TOPIC",
                      help="the arm's sensor_msgs/JointState (with --urdf and --ee-frame)")
    p.add_argument("--urdf", metavar="FILE", help="the arm's URDF, its root the world frame")
    p.add_argument("--ee-frame", metavar="FRAME", help="the URDF's frame sctd moves (the hand)")
    p.add_argument("--object", action="append", default=[], metavar="NAME=TOPIC",
                   help="an object's geometry_msgs/PoseStamped (repeatable): published as objects/NAME")
    p.add_argument("--joy-topic", default="joy", metavar="TOPIC", help="sensor_msgs/Joy (default joy)")
    p.add_argument("--joy-map", metavar="FILE",
                   help="input mapping file for Joy's axes and buttons (docs/input.md; default: the "
                        "xbox map, as the joy package's game_controller_node numbers them)")
    p.add_argument("--device", default="ros", help="the input device name: input/<device> (default ros)")
    p.add_argument("--target-topic", default="sctd/target_pose", metavar="TOPIC",
                   help="the target as geometry_msgs/PoseStamped (default sctd/target_pose)")
    p.add_argument("--target-rate", type=float, default=100.0, metavar="HZ",
                   help="at most this many targets a second out (default 100)")
    p.add_argument("--twist-topic", metavar="TOPIC",
                   help="also the target's velocity as geometry_msgs/TwistStamped (MoveIt Servo's twist "
                        "input); a zero twist once on hold, fault, stop or when targets stop")
    p.add_argument("--diagnostics-topic", default="diagnostics", metavar="TOPIC",
                   help="status as diagnostic_msgs/DiagnosticArray (default diagnostics)")
    p.add_argument("--markers-topic", default="sctd/skill_markers", metavar="TOPIC",
                   help="the active skill's state at the hand as visualization_msgs/MarkerArray for RViz "
                        "(default sctd/skill_markers; '' for none)")
    p.add_argument("--timeout", type=float, default=0.1, metavar="S",
                   help="a message stamped older (or further ahead) than this is stale: dropped and counted "
                        "(default 0.1, the daemon's input and state timeouts)")
    p.add_argument("--qos-depth", type=int, default=1, metavar="N",
                   help="history depth of the command topics (default 1: the newest wins)")
    p.add_argument("--qos-reliability", choices=("reliable", "best_effort"), default="reliable",
                   help="reliability of the command topics (default reliable)")
    p.add_argument("--ros-domain", type=int, default=None, metavar="N",
                   help="ROS_DOMAIN_ID (default: the environment's, else 0)")
    p.add_argument("--node-name", default="sctd_ros", help="the node's name (default sctd_ros)")
    p.add_argument("--namespace", default="", help="the node's namespace (relative topics are in it)")
    p.add_argument("--seconds", type=float, default=None, metavar="S", help="stop after S seconds")
    p.add_argument("--stats-json", action="store_true",
                   help="on exit, print what the bridge did as JSON (received, dropped by reason, sent)")
    add_zenoh_arguments(p)


def options_from(args: argparse.Namespace) -> tuple[BridgeOptions, dict[str, str]] | str:
    """The bridge's options and the objects' topics, or what is wrong with the flags."""
    if args.joint_states_topic and not (args.urdf and args.ee_frame):
        return "--joint-states-topic needs --urdf and --ee-frame"
    if (args.urdf or args.ee_frame) and not args.joint_states_topic:
        return "--urdf and --ee-frame go with --joint-states-topic"
    objects: dict[str, str] = {}
    for item in args.object:
        name, sep, topic = item.partition("=")
        if not sep or not name or not topic or "/" in name:
            return f"--object {item!r}: expected NAME=TOPIC (NAME without '/')"
        if name in objects:
            return f"--object {name}: given twice"
        objects[name] = topic
    if not args.target_rate > 0 or not args.timeout > 0 or args.qos_depth < 1:
        return "--target-rate and --timeout must be > 0, --qos-depth >= 1"
    if args.ros_domain is not None and not 0 <= args.ros_domain <= 232:
        return f"--ros-domain {args.ros_domain}: 0-232"
    return BridgeOptions(robot=args.robot, world_frame=args.world_frame, device=args.device,
                         timeout=args.timeout, target_rate=args.target_rate, twist=bool(args.twist_topic),
                         objects=tuple(objects)), objects


class RosSide:
    """The rclpy node: its subscriptions feed ``bridge``, its publishers are what the
    bridge publishes (a context manager: destroys the node)."""

    def __init__(self, args: argparse.Namespace, objects: dict[str, str], bridge_of, context: Any):
        import rclpy
        from geometry_msgs.msg import PoseStamped
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import JointState, Joy

        self.node = rclpy.create_node(args.node_name, namespace=args.namespace or None, context=context)
        sensor = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                            reliability=ReliabilityPolicy.BEST_EFFORT)
        command = QoSProfile(depth=args.qos_depth, history=HistoryPolicy.KEEP_LAST,
                             reliability=ReliabilityPolicy.RELIABLE if args.qos_reliability == "reliable"
                             else ReliabilityPolicy.BEST_EFFORT)
        m = ros_messages()
        pub = self.node.create_publisher
        self.publishers = {"target": pub(m.PoseStamped, args.target_topic, command),
                           "diagnostics": pub(m.DiagnosticArray, args.diagnostics_topic, 10)}
        if args.twist_topic:
            self.publishers["twist"] = pub(m.TwistStamped, args.twist_topic, command)
        if args.markers_topic:
            from visualization_msgs.msg import MarkerArray

            self.publishers["markers"] = pub(MarkerArray, args.markers_topic, 1)
        self.bridge: Bridge = bridge_of(lambda what, msg: self.publishers[what].publish(msg))
        n, b = self.node, self.bridge
        if args.pose_topic:
            n.create_subscription(PoseStamped, args.pose_topic, b.on_pose, sensor)
        if args.joint_states_topic:
            n.create_subscription(JointState, args.joint_states_topic, b.on_joint_state, sensor)
        for name, topic in objects.items():
            n.create_subscription(PoseStamped, topic, lambda msg, name=name: b.on_object(name, msg), sensor)
        self.pushed = threading.Event()  # the Joy began a push at rest: the outbound thread looks now
        if args.joy_topic:
            n.create_subscription(Joy, args.joy_topic, self._on_joy, sensor)

    def _on_joy(self, msg: Any) -> None:
        if self.bridge.on_joy(msg):
            self.pushed.set()

    def __enter__(self) -> RosSide:
        return self

    def __exit__(self, *exc: object) -> None:
        self.node.destroy_node()


def run(args: argparse.Namespace) -> int:
    """``sctd ros``: bridge until SIGTERM, Ctrl-C or ``--seconds``; exit code."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stderr)
    got = options_from(args)
    if isinstance(got, str):
        return fail("ros", got)
    options, objects = got
    try:
        fk = _kinematics(args)
    except ValueError as e:
        return fail("ros", str(e))
    from sctd_services.input.device import InputError
    from sctd_services.input.mapping import joy_function

    try:
        joy_map = joy_function(args.joy_map)
    except (InputError, OSError) as e:
        return fail("ros", f"--joy-map: {e}")
    import rclpy

    # One Zenoh receive thread, not two: the daemon's target arrives every millisecond,
    # and two workers of Zenoh's receive runtime wake for each (unless the person set
    # the runtime themselves); read once, when the first session opens
    os.environ.setdefault("ZENOH_RUNTIME", ZENOH_RUNTIME)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=args.ros_domain)
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        with session_from_args(args) as session:
            counts = _serve(args, session, context, stop,
                            lambda put, publish: Bridge(options, put, publish, time.time, ros_messages(),
                                                        joy_map, fk), objects)
    finally:
        signal.signal(signal.SIGTERM, previous)
        rclpy.try_shutdown(context=context)
    if args.stats_json:
        print(json.dumps(counts), flush=True)
    print("sctd ros: stopped", file=sys.stderr, flush=True)
    return EXIT_OK


def _serve(args: argparse.Namespace, session: Any, context: Any, stop: threading.Event, make_bridge,
           objects: dict[str, str]) -> dict[str, Any]:
    """Spin the node on ``session`` until ``stop`` or ``--seconds``; the bridge's counts."""
    from rclpy.experimental import EventsExecutor

    keys = Keys(args.robot)
    publishers: dict[str, Any] = {}

    def put(key: str, payload: bytes) -> None:
        pub = publishers.get(key)
        if pub is None:
            pub = publishers[key] = session.declare_publisher(key)
        pub.put(payload)

    end = math.inf if args.seconds is None else time.monotonic() + args.seconds
    done = threading.Event()  # the outbound thread saw the stop (or the end), or failed
    with RosSide(args, objects, lambda publish: make_bridge(put, publish), context) as side:
        # rclpy's events executor queues ready entities in C++ instead of rebuilding a wait
        # set in Python on each wake: 0.185-0.196 of a core against 0.212-0.233 for the
        # single-threaded executor, three runs each (docs/benchmarks.md)
        executor = EventsExecutor(context=context)
        executor.add_node(side.node)
        try:
            with _Outbound(session, keys, side.bridge, side.pushed, args,
                           lambda: stop.is_set() or time.monotonic() >= end, done):
                print(f"sctd ros: node {side.node.get_fully_qualified_name()} on sctd/{args.robot}, "
                      f"domain {context.get_domain_id()}", file=sys.stderr, flush=True)
                while not done.is_set():
                    executor.spin_once(timeout_sec=0.1)  # (and the main thread runs signal handlers)
        except KeyboardInterrupt:
            pass
        finally:
            executor.shutdown()
            for pub in publishers.values():
                pub.undeclare()
        return side.bridge.counts.as_dict()


class _Outbound:
    """sctd -> ROS on a thread of its own (module doc): the target and the status taken
    from Zenoh rings at the target rate (at least :data:`WATCH_RATE`), the bridge's
    watch and the skill's markers on the same wake-ups; each target as it arrives while
    the bridge expects the first motion (a context manager: stops the thread)."""

    def __init__(self, session: Any, keys: Keys, bridge: Bridge, pushed: threading.Event,
                 args: argparse.Namespace, until: Callable[[], bool], done: threading.Event):
        import zenoh

        self.bridge, self.pushed, self.until, self.done = bridge, pushed, until, done
        self.period = 1.0 / max(args.target_rate, WATCH_RATE)
        self.follower = _SkillFollower(session, keys, bridge) if args.markers_topic else None
        self.target = session.declare_subscriber(keys.target, zenoh.handlers.RingChannel(1))
        # statuses in order (10-50 Hz): a hold between two wake-ups still ends the twist
        self.status = session.declare_subscriber(keys.status, zenoh.handlers.RingChannel(64))
        self._stop = threading.Event()
        self.error: Exception | None = None
        self._thread = threading.Thread(target=self._run, name="sctd-ros-out", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        """Until ``until()`` (or a failure, raised again at exit), then ``done``: the
        executor stops too."""
        try:
            self._loop()
        except Exception as e:  # raised again in __exit__, on the main thread
            self.error = e
        finally:
            self.done.set()

    def _loop(self) -> None:
        due = markers = time.monotonic()
        while not self._stop.is_set() and not self.until():
            if self.pushed.wait(max(0.0, due - time.monotonic())):
                self.pushed.clear()
                self._follow_push()
                due = time.monotonic()  # the schedule restarts from the first motion
            now = time.monotonic()
            due = due + self.period if now - due < self.period else now + self.period
            self._take()
            self.bridge.watch()
            if self.follower is not None and now >= markers:
                markers = now + MARKERS_PERIOD
                self.follower.step()

    def _take(self) -> None:
        """The newest target, and every status that came, to the bridge."""
        sample = self.target.try_recv()
        if sample is not None:
            self.bridge.on_target(sample.payload.to_bytes())
        while (sample := self.status.try_recv()) is not None:
            self.bridge.on_status(sample.payload.to_bytes())

    def _follow_push(self) -> None:
        """Each target as it arrives, until the bridge has sent the first that moved (or
        the push moved nothing within the bridge's timeout)."""
        while self.bridge.expects_motion() and not self._stop.is_set():
            sample = self.target.try_recv()
            if sample is None:
                time.sleep(POLL)
            else:
                self.bridge.on_target(sample.payload.to_bytes())

    def __enter__(self) -> _Outbound:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self.pushed.set()
        self._thread.join(5.0)
        self.target.undeclare()
        self.status.undeclare()
        if self.follower is not None:
            self.follower.close()
        if self.error is not None:
            raise self.error


class _SkillFollower:
    """Fetches the daemon's active skill (``skill/bundle``, beside the executor) whenever
    the status names another, and hands it to the bridge for its markers."""

    def __init__(self, session: Any, keys: Keys, bridge: Bridge):
        from sctd_services.view.service import BundleFetcher

        self.bridge, self.fetcher = bridge, BundleFetcher(session, keys)
        self.drawn: str | None = None

    def step(self) -> None:
        wanted = self.bridge.skill_id
        if wanted and wanted != self.drawn:
            self.fetcher.want(wanted)
        done = self.fetcher.take()
        if done is not None and done[0] is not None:
            from .markers import marker_messages

            self.bridge.set_skill(done[0], marker_messages())
            self.drawn = done[1]

    def close(self) -> None:
        self.fetcher.__exit__(None, None, None)


def _kinematics(args: argparse.Namespace) -> Any:
    """The forward kinematics of ``--urdf`` to ``--ee-frame`` (None without
    ``--joint-states-topic``); ValueError naming the problem."""
    if not args.joint_states_topic:
        return None
    from .kinematics import ForwardKinematics

    return ForwardKinematics(args.urdf, args.ee_frame)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="sctd ros")
    add_arguments(p)
    args = p.parse_args(argv)
    return run(args) if args else EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
