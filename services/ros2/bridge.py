"""What ``sctd ros`` does with each message, apart from how messages travel.

:class:`Bridge` turns ROS 2 messages (rclpy's classes, or anything with the fields of
the ROS definitions) into sctd's wire messages and sctd's into ROS 2 messages. It is
handed two functions, ``put(key, payload)`` towards Zenoh and ``publish(what, msg)``
towards ROS, and a clock; the node (:mod:`.node`) wires them to a Zenoh session and an
rclpy node. So every rule below is tested on messages, without DDS.

In (ROS -> sctd), each message checked by :mod:`sctd.wire.rosmsg` (the rules of both of
sctd's ROS paths) and dropped and counted by reason when it fails them:

- the hand: ``geometry_msgs/PoseStamped`` -> ``state`` (``pose``), or
  ``sensor_msgs/JointState`` -> ``state`` (``q`` and the pose by forward kinematics,
  :class:`~.kinematics.ForwardKinematics`); the header stamp is sctd's ``stamp``;
- each object: ``PoseStamped`` -> ``objects/<name>``;
- the person: ``sensor_msgs/Joy`` -> ``input/<device>`` through an input mapping file.

Out (sctd -> ROS):

- ``target`` -> ``PoseStamped`` at most ``target_rate`` Hz (the newest) on a schedule,
  except that a target that moves after rest (the last two published were the same
  pose) goes out at once, and the schedule restarts from it; and, where asked,
  ``TwistStamped``: the target's velocity over the last published interval, zero once
  when the daemon holds, faults or stops, or when targets stop coming;
- ``status`` -> ``diagnostic_msgs/DiagnosticArray`` (at most 2 Hz, and at once when the
  mode changes);
- the active skill (:meth:`Bridge.set_skill`, the node fetches it) ->
  ``visualization_msgs/MarkerArray``: its active state at the hand, for RViz
  (:mod:`.markers`), at most 2 Hz and at once when the state changes.

Nothing from ROS reaches ``target``: the daemon moves the target only with the person's
input, as on its own keys; the bridge only carries what the robot and the perception
report, and the person's Joy.
"""

from __future__ import annotations

import math
import threading
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from sctd import se3
from sctd.wire import Keys, codec, rosmsg

DIAGNOSTICS_PERIOD = 0.5  # s between diagnostics (and at once on a change of mode)
MARKERS_PERIOD = 0.5  # s between the skill's markers (and at once on a change of state)
HOLDING = ("waiting", "hold", "fault", "stopped")  # the daemon's modes that move nothing
SLACK = 0.05  # of a period: a target this early is due (a taker waking on its own clock)

JoyMap = Callable[[tuple[float, ...], tuple[int, ...]], tuple[list[float], list[int], bool]]


@dataclass(frozen=True)
class BridgeOptions:
    """What the bridge is configured with (``sctd ros``'s flags, ``docs/ros2.md``)."""

    robot: str = "edan"
    world_frame: str = "world"
    device: str = "ros"  # the input device name: input/<device>
    timeout: float = 0.1  # s: an in-message older (or further ahead) than this is stale
    target_rate: float = 100.0  # Hz, at most, of PoseStamped (and TwistStamped) out
    twist: bool = False  # publish the target's velocity as TwistStamped too
    objects: tuple[str, ...] = ()  # the object names, in the order of their topics


@dataclass
class Counts:
    """What the bridge did, by kind of message: received (used), dropped by reason, sent."""

    received: Counter[str] = field(default_factory=Counter)
    dropped: dict[str, Counter[str]] = field(default_factory=dict)
    sent: Counter[str] = field(default_factory=Counter)

    def drop(self, kind: str, reason: str) -> None:
        self.dropped.setdefault(kind, Counter())[reason] += 1

    def as_dict(self) -> dict[str, Any]:
        return {"received": dict(self.received), "sent": dict(self.sent),
                "dropped": {k: dict(v) for k, v in self.dropped.items()}}


class Bridge:
    """The rules of ``sctd ros`` (module doc).

    Parameters
    ----------
    options : BridgeOptions
    put : callable(key, payload)
        Puts an sctd message on its Zenoh key.
    publish : callable(what, msg)
        Publishes a ROS message: ``what`` is ``target``, ``twist`` or ``diagnostics``.
    clock : callable() -> float
        This machine's time (Unix s), which stamps are judged against.
    messages : module-like
        The ROS message classes by name (``PoseStamped``, ``TwistStamped``,
        ``DiagnosticArray``, ``DiagnosticStatus``, ``KeyValue``): :func:`ros_messages`.
    joy_map : callable, optional
        ``(axes, buttons) -> (u, [mode, enable, escape], stop)`` (an input mapping file).
    fk : callable, optional
        JointState positions (the model's order) -> the hand's pose ``[7]``, with
        ``joint_names`` (for JointState in).
    """

    def __init__(self, options: BridgeOptions, put: Callable[[str, bytes], None],
                 publish: Callable[[str, Any], None], clock: Callable[[], float], messages: Any,
                 joy_map: JoyMap | None = None, fk: Any = None):
        self.options, self.put, self.publish, self.clock = options, put, publish, clock
        self.msgs, self.joy_map, self.fk = messages, joy_map, fk
        self.keys = Keys(options.robot)
        self.counts = Counts()
        self._lock = threading.Lock()  # callbacks come from rclpy's and Zenoh's threads
        self._seq: Counter[str] = Counter()
        self._due = -math.inf  # when the next target may be published (Unix s)
        self._last_pose: tuple[float, list[float]] | None = None  # (stamp, pose) of that target
        self._last_target = -math.inf  # when the newest target arrived
        self._resting = False  # the last two targets published had the same pose
        self._last_pose_sent: list[float] | None = None  # the pose of the last target published
        self._push_at = -math.inf  # when the person's Joy last began a push (at rest)
        self._pushing = False  # the newest Joy pushes (enable held, a non-zero axis)
        self._moving = False  # a non-zero twist was the last one sent
        self._mode: str | None = None
        self._last_diag = -math.inf
        self.hand: list[float] | None = None  # the newest hand pose (world) used
        self.object_poses: dict[str, list[float]] = {}  # the newest of each object used
        self.skill_id: str | None = None  # the skill the daemon's status names
        self._markers: Any = None  # SkillMarkers of the skill drawn
        self._drawn: tuple[str, str] | None = None  # (skill id, state) of the last markers
        self._last_markers = -math.inf

    # -- ROS -> sctd -------------------------------------------------------------------
    def _next(self, what: str) -> int:
        self._seq[what] += 1
        return self._seq[what]

    def on_pose(self, msg: Any) -> None:
        """The hand's ``PoseStamped`` -> ``state``."""
        with self._lock:
            try:
                stamp, pose = rosmsg.stamped_pose(msg, self.clock(), self.options.timeout,
                                                  self.options.world_frame)
            except rosmsg.Dropped as e:
                self.counts.drop("pose", e.reason)
                return
            self.counts.received["pose"] += 1
            self.hand = pose
            self.put(self.keys.state, codec.encode_state(self._next("state"), stamp, pose))

    def on_joint_state(self, msg: Any) -> None:
        """The arm's ``JointState`` -> ``state`` with ``q`` and the hand's pose by forward
        kinematics (the joints the model names, found by name)."""
        with self._lock:
            if self.fk is None:
                self.counts.drop("joint_state", "no_model")
                return
            try:
                stamp = rosmsg.judge_stamp(msg.header, self.clock(), self.options.timeout)
                q = rosmsg.joint_positions(msg, self.fk.joint_names)
            except rosmsg.Dropped as e:
                self.counts.drop("joint_state", e.reason)
                return
            pose = self.fk(q)
            if not math.isfinite(sum(pose)):
                self.counts.drop("joint_state", "nonfinite")
                return
            self.counts.received["joint_state"] += 1
            self.hand = pose
            self.put(self.keys.state, codec.encode_state(self._next("state"), stamp, pose, q=q))

    def on_object(self, name: str, msg: Any) -> None:
        """An object's ``PoseStamped`` -> ``objects/<name>``."""
        with self._lock:
            kind = f"objects/{name}"
            try:
                stamp, pose = rosmsg.stamped_pose(msg, self.clock(), self.options.timeout,
                                                  self.options.world_frame)
            except rosmsg.Dropped as e:
                self.counts.drop(kind, e.reason)
                return
            self.counts.received[kind] += 1
            self.object_poses[name] = pose
            self.put(self.keys.objects(name), codec.encode_object(self._next(kind), stamp, pose))

    def on_joy(self, msg: Any) -> bool:
        """The person's ``Joy`` -> ``input/<device>``, through the input mapping; its
        header stamp is the input's stamp (a Joy not repeated within the daemon's input
        timeout times out there: the joy package's autorepeat at 20 Hz or more). True
        when it began a push (enable held, an axis off zero) while the target rests:
        the target is about to move (:meth:`expects_motion`)."""
        with self._lock:
            if self.joy_map is None:
                self.counts.drop("joy", "no_map")
                return False
            try:
                stamp = rosmsg.judge_stamp(msg.header, self.clock(), self.options.timeout)
                axes, buttons = rosmsg.joy_values(msg)
            except rosmsg.Dropped as e:
                self.counts.drop("joy", e.reason)
                return False
            u, roles, stop = self.joy_map(axes, buttons)
            self.counts.received["joy"] += 1
            self.put(self.keys.input(self.options.device),
                     codec.encode_input(self._next("joy"), stamp, u, roles, stop))
            pushing = (len(roles) < 2 or bool(roles[1])) and any(x != 0.0 for x in u) and not stop
            began = pushing and not self._pushing
            self._pushing = pushing
            if began:
                self._push_at = self.clock()
            return began and self._resting

    def expects_motion(self) -> bool:
        """True while the person's push began at rest within the timeout and the target
        has not moved yet: a taker of targets then hands each one over as it arrives,
        so that the first motion goes out at once (:meth:`on_target`)."""
        with self._lock:
            return self._resting and self.clock() - self._push_at <= self.options.timeout

    # -- sctd -> ROS -------------------------------------------------------------------
    def on_target(self, payload: bytes) -> None:
        """``target`` -> ``PoseStamped`` (and ``TwistStamped``), the newest, at most
        ``target_rate`` Hz on a schedule; but the first target that moves after rest
        goes out at once, and the schedule starts again from it (a person's push is not
        held back by up to a period; the rate stays capped). A target is decoded only
        when one is due or the target rests (then only an unmoved one is passed over)."""
        with self._lock:
            now = self.clock()
            self.counts.received["target"] += 1
            self._last_target = now
            period = 1.0 / self.options.target_rate
            due = now >= self._due - SLACK * period
            if not (due or self._resting):
                return
            try:
                target = codec.decode_target(payload)
            except codec.DecodeError as e:
                self.counts.drop("target", e.reason)
                return
            stamp, pose = float(target["stamp"]), [float(v) for v in target["pose"]]
            last = self._last_pose_sent
            if not due:
                if pose == last:
                    return
                self._due = now  # moved after rest: out at once, the schedule from here
                self.counts.sent["target_at_once"] += 1
            # on a schedule, so that targets at 1 kHz give target_rate, not fewer
            self._due = self._due + period if now - self._due < period else now + period
            self._resting, self._last_pose_sent = pose == last, pose
            self.publish("target", self.pose_stamped(stamp, pose))
            self.counts.sent["target"] += 1
            if self.options.twist:
                self._twist(stamp, pose)

    def _twist(self, stamp: float, pose: list[float]) -> None:
        """The target's velocity since the pose the last twist ended at (world frame).
        That pose moves on only with a twist sent, so that the twists add up to the
        targets' motion (none is lost to a target stamped before a zero twist)."""
        last = self._last_pose
        if last is None:
            self._last_pose = (stamp, pose)
            return
        if not stamp > last[0]:
            return
        dt = stamp - last[0]
        v = [(a - b) / dt for a, b in zip(pose[:3], last[1][:3], strict=True)]
        dR = se3.matrix_from_quaternion(pose[3:]) @ se3.matrix_from_quaternion(last[1][3:]).T
        w = (se3.rotvec_from_matrix(dR) / dt).tolist()
        if not math.isfinite(sum(v) + sum(w)):
            self.counts.drop("twist", "nonfinite")
            return
        self.publish("twist", self.twist_stamped(stamp, v, w))
        self.counts.sent["twist"] += 1
        self._moving = any(x != 0.0 for x in (*v, *w))
        self._last_pose = (stamp, pose)

    def stop_twist(self, why: str) -> None:
        """A zero ``TwistStamped`` once, unless the last twist sent was zero (``why``
        counts it)."""
        if not self.options.twist or not self._moving:
            return
        last = self._last_pose
        t = self.clock() if last is None else max(self.clock(), last[0])
        self.publish("twist", self.twist_stamped(t, [0.0] * 3, [0.0] * 3))
        self.counts.sent["twist_zero"] += 1
        self.counts.sent[f"twist_zero_{why}"] += 1
        self._moving = False
        if last is not None:
            # the next velocity is taken from here: the pose last sent, at the zero's stamp,
            # so that the twists add up to the targets' motion (a consumer integrating
            # them by their stamps ends where the targets end)
            self._last_pose = (t, last[1])

    def on_status(self, payload: bytes) -> None:
        """``status`` -> ``DiagnosticArray`` (at most every :data:`DIAGNOSTICS_PERIOD`
        s, at once on a change of mode); a zero twist once when the daemon holds."""
        with self._lock:
            now = self.clock()
            try:
                status = codec.unpack_map(payload)
            except codec.DecodeError as e:
                self.counts.drop("status", e.reason)
                return
            self.counts.received["status"] += 1
            mode = str(status.get("mode"))
            if mode in HOLDING:
                self.stop_twist(mode)
            if mode != self._mode or now - self._last_diag >= DIAGNOSTICS_PERIOD:
                self._mode, self._last_diag = mode, now
                self.publish("diagnostics", self.diagnostics(now, status))
                self.counts.sent["diagnostics"] += 1
            self.skill_id = str(status["skill"]) if status.get("skill") else None
            self._draw(now, status.get("state"))

    def set_skill(self, skill: Any, messages: Any) -> None:
        """Draw ``skill`` (the daemon's active one, fetched by the node) from now on."""
        from .markers import SkillMarkers

        with self._lock:
            self._markers = SkillMarkers(skill, messages, self.options.world_frame)
            self._drawn = None

    def _draw(self, now: float, state: Any) -> None:
        """The active state's markers, if the skill, its object and the hand are known."""
        mk = self._markers
        if mk is None or mk.skill.id != self.skill_id or state not in [s.name for s in mk.skill.states]:
            return
        obj, hand = self.object_poses.get(mk.skill.object), self.hand
        if obj is None or hand is None:
            return
        if self._drawn == (mk.skill.id, state) and now - self._last_markers < MARKERS_PERIOD:
            return
        self._drawn, self._last_markers = (mk.skill.id, str(state)), now
        T_obj, T_hand = se3.transform_from_pose(obj), se3.transform_from_pose(hand)
        self.publish("markers", mk.array(str(state), T_obj, T_hand, rosmsg.time_fields(now)))
        self.counts.sent["markers"] += 1

    def watch(self) -> None:
        """Called periodically: targets that stopped coming (the daemon gone, the link
        down) end the twist with a zero, once."""
        with self._lock:
            if self.clock() - self._last_target > self.options.timeout:
                self.stop_twist("no_target")

    # -- ROS messages ------------------------------------------------------------------
    def _header(self, header: Any, stamp: float) -> None:
        header.stamp.sec, header.stamp.nanosec = rosmsg.time_fields(stamp)
        header.frame_id = self.options.world_frame

    def pose_stamped(self, stamp: float, pose: Sequence[float]) -> Any:
        msg = self.msgs.PoseStamped()
        self._header(msg.header, stamp)
        p, q = msg.pose.position, msg.pose.orientation
        p.x, p.y, p.z = (float(v) for v in pose[:3])
        q.x, q.y, q.z, q.w = (float(v) for v in pose[3:7])
        return msg

    def twist_stamped(self, stamp: float, v: Sequence[float], w: Sequence[float]) -> Any:
        msg = self.msgs.TwistStamped()
        self._header(msg.header, stamp)
        t = msg.twist
        t.linear.x, t.linear.y, t.linear.z = (float(x) for x in v)
        t.angular.x, t.angular.y, t.angular.z = (float(x) for x in w)
        return msg

    def diagnostics(self, now: float, status: dict[str, Any]) -> Any:
        """One ``DiagnosticStatus`` named ``sctd/<robot>``: OK while running, WARN while
        waiting or stopped, ERROR on hold or fault; the mode, skill, state, stuck state,
        counters and this bridge's counts as key/values."""
        m = self.msgs
        level = {"running": m.DiagnosticStatus.OK, "waiting": m.DiagnosticStatus.WARN,
                 "stopped": m.DiagnosticStatus.WARN}.get(str(status.get("mode")), m.DiagnosticStatus.ERROR)
        st = m.DiagnosticStatus(level=level, name=f"sctd/{self.options.robot}",
                                hardware_id=self.options.robot, message=_words(status))
        values = {"mode": status.get("mode"), "skill": status.get("skill_name"),
                  "skill_id": status.get("skill"), "state": status.get("state"), "stuck": status.get("stuck"),
                  "counters": status.get("counters"), "bridge": self.counts.as_dict()}
        st.values = [m.KeyValue(key=k, value=str(v)[:1000]) for k, v in values.items()]
        arr = m.DiagnosticArray()
        self._header(arr.header, now)
        arr.status = [st]
        return arr


def _words(status: dict[str, Any]) -> str:
    mode = str(status.get("mode"))
    words = {"running": "running", "waiting": "waiting for the robot's state and the object's pose",
             "hold": "holding: stale state or object pose", "fault": "holding: the robot's state jumped",
             "stopped": "stopped: no input or the deadman released"}.get(mode, mode)
    return f"{words}; state {status.get('state')}"


def ros_messages() -> Any:
    """The ROS message classes the bridge builds (needs the ``ros2`` extra)."""
    from types import SimpleNamespace

    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import PoseStamped, TwistStamped

    return SimpleNamespace(PoseStamped=PoseStamped, TwistStamped=TwistStamped,
                           DiagnosticArray=DiagnosticArray, DiagnosticStatus=DiagnosticStatus,
                           KeyValue=KeyValue)
