"""The ROS 2 side of ``sctd ros``'s end-to-end tests (tests/test_ros2_node.py): real rclpy
nodes, run as ``python -m tests.ros2_side`` inside a network namespace the test made.

- ``arm``: a ROS 2 arm. It follows the ``PoseStamped`` target (``sctd/target_pose``) and
  publishes its hand's pose (``ee_pose``) and joint states (``joint_states``). Behind it
  is sctd's simulator on a robot prefix of its own (``sctd/<arm>/...``, never the
  daemon's): the physics and the task's own judgement of the pour, as a real arm and a
  real mug would be.
- ``perception``: the task's objects as an AprilTag detector would publish them, one
  ``PoseStamped`` per object (``<name>_pose``), from the simulator's bodies.
- ``joy``: a joystick: each input message of the simulated person (on the daemon's
  prefix, ``input/<device>``, which the daemon does not follow) becomes a ``Joy``:
  axes ``u``, buttons ``[mode, enable, escape]``, stamped with the message's stamp.
- ``twist``: a consumer of ``TwistStamped`` that integrates it into a pose and prints,
  at the end, what it integrated and the zero twists it saw (JSON).
- ``rviz``: what RViz would get of the skill: the ``MarkerArray`` on
  ``sctd/skill_markers``, whose labels it reports at the end.

Also relays the simulator's ``scene`` (the task's progress, which no ROS message
carries) to the daemon's prefix for the simulated person, who judges when it is done.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
import time

import numpy as np
import zenoh

from sctd import se3
from sctd.wire import Keys, codec
from sctd.wire.session import close_session, open_session


def _stamp(header, t: float, frame: str) -> None:
    header.stamp.sec = int(t)
    header.stamp.nanosec = min(round((t - int(t)) * 1e9), 999_999_999)
    header.frame_id = frame


def _pose_msg(t: float, pose, frame: str = "world"):
    from geometry_msgs.msg import PoseStamped

    m = PoseStamped()
    _stamp(m.header, t, frame)
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in pose[:3])
    q = m.pose.orientation
    q.x, q.y, q.z, q.w = (float(v) for v in pose[3:7])
    return m


def arm(node, session: zenoh.Session, keys: Keys, joints: list[str]) -> list:
    """Target in (ROS) -> the simulator's target; its state -> ee_pose and joint_states."""
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState

    ee = node.create_publisher(PoseStamped, "ee_pose", 10)
    js = node.create_publisher(JointState, "joint_states", 10)
    seq = [0]

    def on_target(m) -> None:
        p, q = m.pose.position, m.pose.orientation
        t = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        seq[0] += 1
        session.put(keys.target, codec.encode_target(seq[0], t, [p.x, p.y, p.z, q.x, q.y, q.z, q.w],
                                                     "ros", "ros", -1))

    def on_state(s: zenoh.Sample) -> None:
        st = codec.decode_state(s.payload.to_bytes())
        ee.publish(_pose_msg(st.stamp, st.pose))
        if st.q is not None:
            m = JointState()
            _stamp(m.header, st.stamp, "")
            m.name, m.position = list(joints), [float(x) for x in st.q]
            js.publish(m)

    node.create_subscription(PoseStamped, "sctd/target_pose", on_target, 10)
    return [session.declare_subscriber(keys.state, on_state)]


def perception(node, session: zenoh.Session, keys: Keys, frames: list[str]) -> list:
    from geometry_msgs.msg import PoseStamped

    subs = []
    for name in frames:
        pub = node.create_publisher(PoseStamped, f"{name}_pose", 10)

        def on_object(s: zenoh.Sample, pub=pub) -> None:
            o = codec.decode_object(s.payload.to_bytes())
            pub.publish(_pose_msg(o.stamp, o.pose))
        subs.append(session.declare_subscriber(keys.objects(name), on_object))
    return subs


def joy(node, session: zenoh.Session, keys: Keys, device: str) -> list:
    from sensor_msgs.msg import Joy

    pub = node.create_publisher(Joy, "joy", 10)

    def on_input(s: zenoh.Sample) -> None:
        i = codec.decode_input(s.payload.to_bytes())
        m = Joy()
        _stamp(m.header, i.stamp, "joy")
        m.axes = [float(x) for x in i.u[:3]]
        m.buttons = [int(b) for b in (i.buttons or (0, 1, 0))]
        pub.publish(m)
    return [session.declare_subscriber(keys.input(device), on_input)]


class Integrator:
    """Integrates TwistStamped (world frame, by header stamps) from the target with the
    stamp of the first twist it takes (a twist and its target share their stamp); counts
    the stops (a zero twist after motion)."""

    def __init__(self):
        self.pose: np.ndarray | None = None  # 4x4
        self.targets: dict[float, list] = {}  # stamp -> pose, until the start
        self.last: float | None = None
        self.moving = False
        self.zeros = 0
        self.received = 0
        self.lock = threading.Lock()

    def target(self, stamp: float, pose) -> None:
        with self.lock:
            if self.pose is None and len(self.targets) < 10_000:
                self.targets[stamp] = pose

    def on_twist(self, m) -> None:
        t = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        v = np.array([m.twist.linear.x, m.twist.linear.y, m.twist.linear.z])
        w = np.array([m.twist.angular.x, m.twist.angular.y, m.twist.angular.z])
        with self.lock:
            self.received += 1
            if self.pose is None:  # start where this twist ends: its target
                if t in self.targets:
                    self.pose, self.last, self.targets = se3.transform_from_pose(self.targets[t]), t, {}
                return
            moving = bool(v.any() or w.any())
            if self.moving and not moving:
                self.zeros += 1
            self.moving = moving
            if moving and self.last is not None and t > self.last:
                dt = t - self.last
                self.pose[:3, 3] += v * dt
                self.pose[:3, :3] = se3.matrix_from_rotvec(w * dt) @ self.pose[:3, :3]
            self.last = t


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tests.ros2_side")
    p.add_argument("--connect", required=True)
    p.add_argument("--robot", default="edan", help="the daemon's prefix")
    p.add_argument("--arm", default="arm", help="the simulator's prefix")
    p.add_argument("--frame", action="append", default=[], help="an object the perception publishes")
    p.add_argument("--joint", action="append", default=[], help="the arm's joints, in order")
    p.add_argument("--joy-from", default="simuser", help="the person's input device on the daemon's prefix")
    p.add_argument("--twist", action="store_true", help="integrate sctd/twist and report it")
    p.add_argument("--seconds", type=float, default=120.0)
    args = p.parse_args(argv)
    import rclpy
    from geometry_msgs.msg import PoseStamped, TwistStamped
    from rclpy.executors import SingleThreadedExecutor

    rclpy.init()
    session = open_session(connect=[args.connect])
    robot, sim = Keys(args.robot), Keys(args.arm)
    nodes = {name: rclpy.create_node(f"test_{name}")
             for name in ("arm", "perception", "joy", "twist", "rviz")}
    subs = arm(nodes["arm"], session, sim, args.joint)
    subs += perception(nodes["perception"], session, sim, args.frame)
    subs += joy(nodes["joy"], session, robot, args.joy_from)
    scene: list = [None]

    def relay(s: zenoh.Sample) -> None:
        data = s.payload.to_bytes()
        scene[0] = codec.unpack_map(data)
        session.put(robot.scene, data)
    subs.append(session.declare_subscriber(sim.scene, relay))
    from visualization_msgs.msg import MarkerArray

    labels: set[str] = set()
    arrays = [0]

    def on_markers(arr) -> None:
        arrays[0] += 1
        labels.update(m.text for m in arr.markers if m.ns == "labels" and ":" in m.text)
    nodes["rviz"].create_subscription(MarkerArray, "sctd/skill_markers", on_markers, 10)
    integrator = Integrator()
    if args.twist:
        # a deep queue: the consumer integrates every twist, and this process's executor
        # also serves the arm's relays at 1 kHz (a lag of more than 10 twists lost some)
        nodes["twist"].create_subscription(TwistStamped, "sctd/twist", integrator.on_twist, 1000)
        target: list = [None]

        def on_target(m) -> None:
            p_, q = m.pose.position, m.pose.orientation
            pose = [p_.x, p_.y, p_.z, q.x, q.y, q.z, q.w]
            integrator.target(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, pose)
            target[0] = pose
        nodes["twist"].create_subscription(PoseStamped, "sctd/target_pose", on_target, 1000)
    executor = SingleThreadedExecutor()
    for n in nodes.values():
        executor.add_node(n)
    stopping = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stopping.set())
    print(json.dumps({"ready": True}), flush=True)
    end = time.monotonic() + args.seconds
    try:
        while time.monotonic() < end and not stopping.is_set():
            executor.spin_once(timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    finally:
        for s in subs:
            s.undeclare()
        executor.shutdown()
        for n in nodes.values():
            n.destroy_node()
        rclpy.try_shutdown()
        close_session(session)
    out: dict = {"scene": scene[0], "marker_arrays": arrays[0], "marker_labels": sorted(labels)}
    if args.twist:
        with integrator.lock:
            out.update(received=integrator.received, zeros=integrator.zeros,
                       integrated=None if integrator.pose is None else
                       se3.pose_from_transform(integrator.pose).tolist(), target=target[0])
    print(json.dumps(out, default=str), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
