"""ROS 2 (Jazzy) over rmw_zenoh without a ROS install (``--ros``, docs/ros2.md).

rmw_zenoh maps a ROS 2 topic onto one Zenoh key and announces the graph with liveliness
tokens; a program that puts CDR on that key, with rmw_zenoh's attachment, and declares
the same tokens is a ROS 2 node to every rmw_zenoh node on the same Zenoh network
(``ros2 topic list/echo``, RViz). The formats, and where each comes from, are in
docs/ros2.md:

- data key: ``<domain>/<topic without the leading slash>/<pkg>::msg::dds_::<Name>_/<RIHS01 hash>``
- liveliness token: ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|MS>/<enclave>/
  <namespace>/<node>[/<topic>/<type>/<hash>/<qos>]`` with ``/`` in names written ``%``
- attachment: int64 sequence number, int64 source timestamp (ns, Unix), 16-byte GID,
  in Zenoh's serialization format (little-endian integers, a length-prefixed byte array)
- GID: XXH3-128 of the entity's liveliness token, low 64 bits first, little-endian.

CDR and the type hashes come from rosbags' Jazzy typestore. Nothing here runs on the
daemon's tick thread: targets are encoded by its publisher thread, Joy messages are
decoded in the Zenoh subscriber's callback.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import xxhash
import zenoh
import zenoh.ext
from rosbags.typesys import Stores, get_typestore

from . import codec, rosmsg
from .ros_options import check_namespace
from .session import MSGPACK

POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
JOY = "sensor_msgs/msg/Joy"
ADMIN_SPACE = "@ros2_lv"
NODE, PUBLISHER, SUBSCRIPTION = "NN", "MP", "MS"
# rmw_zenoh writes a QoS as its differences from the default profile (reliable, volatile,
# keep last 10, no deadline/lifespan, automatic liveliness): all fields empty.
DEFAULT_QOS = "::,:,:,:,,"
CDR = zenoh.Encoding.APPLICATION_CDR
WORLD_FRAME = "world"
MAX_JOY_BYTES = 4096  # a Joy with 6 axes and 21 buttons is under 200 bytes
MAX_JOY_VALUES = rosmsg.MAX_VALUES  # axes or buttons in one Joy

STORE = get_typestore(Stores.ROS2_JAZZY)


class RosError(ValueError):
    """A ROS name or setting sctd cannot use (the message names which and why)."""


def dds_type(type_name: str) -> str:
    """``pkg/msg/Name`` as rmw_zenoh writes it in keys: ``pkg::msg::dds_::Name_``."""
    pkg, kind, name = _split_type(type_name)
    return f"{pkg}::{kind}::dds_::{name}_"


def _split_type(type_name: str) -> tuple[str, str, str]:
    parts = type_name.split("/")
    if len(parts) != 3 or not all(parts):
        raise RosError(f"type {type_name!r}: expected pkg/msg/Name")
    return parts[0], parts[1], parts[2]


def type_hash(type_name: str) -> str:
    """The RIHS01 type hash (REP-2011) of a Jazzy message type, ``RIHS01_<64 hex>``."""
    return str(STORE.hash_rihs01(type_name))


def topic_name(namespace: str, name: str) -> str:
    """The fully qualified topic ``name`` in ``namespace``."""
    ns = check_namespace(namespace)
    return f"{ns.rstrip('/')}/{name}"


def data_key(domain: int, topic: str, type_name: str) -> str:
    """The Zenoh key rmw_zenoh publishes ``topic`` of ``type_name`` on."""
    return f"{domain}/{topic.strip('/')}/{dds_type(type_name)}/{type_hash(type_name)}"


def _mangle(name: str) -> str:
    return name.replace("/", "%")


def liveliness_token(domain: int, zid: str, node_id: int, entity_id: int, kind: str,
                     namespace: str, node: str, topic: str | None = None,
                     type_name: str | None = None, enclave: str = "/",
                     qos: str = DEFAULT_QOS) -> str:
    """The liveliness key rmw_zenoh declares for a node (``NN``, no topic) or a
    publisher/subscription (``MP``/``MS``) of ``topic``."""
    parts = [ADMIN_SPACE, str(domain), zid, str(node_id), str(entity_id), kind,
             _mangle(enclave), _mangle(namespace), _mangle(node)]
    if kind != NODE:
        if topic is None or type_name is None:
            raise RosError(f"a {kind} token needs a topic and a type")
        parts += [_mangle(topic), dds_type(type_name), type_hash(type_name), qos]
    return "/".join(parts)


def gid(token: str) -> bytes:
    """An entity's 16-byte GID: XXH3-128 of its liveliness token, low half first."""
    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(16, "little")


def attachment(seq: int, stamp_ns: int, source_gid: bytes) -> bytes:
    """rmw_zenoh's per-message attachment (Jazzy 0.2.4 and later)."""
    return zenoh.ext.z_serialize((zenoh.ext.Int64(seq), zenoh.ext.Int64(stamp_ns),
                                  source_gid)).to_bytes()


def parse_attachment(data: bytes) -> tuple[int, int, bytes]:
    """``(sequence number, source timestamp ns, GID)`` of an attachment."""
    seq, stamp, g = zenoh.ext.z_deserialize(tuple[zenoh.ext.Int64, zenoh.ext.Int64, bytes],
                                            zenoh.ZBytes(data))
    if len(g) != 16:
        raise ValueError(f"attachment GID: {len(g)} bytes, expected 16")
    return int(seq), int(stamp), bytes(g)


# --- messages ----------------------------------------------------------------------------

def _header(stamp: float, frame: str) -> Any:
    T = STORE.types["builtin_interfaces/msg/Time"]
    try:
        sec, nsec = rosmsg.time_fields(stamp)
    except ValueError as e:
        raise RosError(str(e)) from None
    return STORE.types["std_msgs/msg/Header"](T(sec, nsec), frame)


def encode_pose_stamped(stamp: float, pose: Sequence[float], frame: str = WORLD_FRAME) -> bytes:
    """``geometry_msgs/msg/PoseStamped`` CDR of an sctd pose ``[x, y, z, qx, qy, qz, qw]``
    stamped ``stamp`` (Unix s)."""
    t = STORE.types
    x, y, z, qx, qy, qz, qw = (float(v) for v in pose)
    msg = t[POSE_STAMPED](_header(stamp, frame), t["geometry_msgs/msg/Pose"](
        t["geometry_msgs/msg/Point"](x, y, z), t["geometry_msgs/msg/Quaternion"](qx, qy, qz, qw)))
    return bytes(STORE.serialize_cdr(msg, POSE_STAMPED))


def decode_pose_stamped(data: bytes) -> tuple[float, str, list[float]]:
    """``(stamp, frame id, pose [x, y, z, qx, qy, qz, qw])`` of a PoseStamped CDR."""
    m: Any = STORE.deserialize_cdr(data, POSE_STAMPED)
    p, q = m.pose.position, m.pose.orientation
    stamp = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
    return stamp, m.header.frame_id, [p.x, p.y, p.z, q.x, q.y, q.z, q.w]


def encode_joy(stamp: float, axes: Sequence[float], buttons: Sequence[int],
               frame: str = "joy") -> bytes:
    msg = STORE.types[JOY](_header(stamp, frame), np.array(axes, dtype=np.float32),
                           np.array(buttons, dtype=np.int32))
    return bytes(STORE.serialize_cdr(msg, JOY))


JoyError = rosmsg.Dropped  # a Joy that is not used; ``reason`` is its drop counter's name


def decode_joy(data: bytes, now: float, timeout: float) -> tuple[float, tuple[float, ...], tuple[int, ...]]:
    """``(stamp, axes, buttons)`` of a ``sensor_msgs/msg/Joy`` CDR whose header stamp is
    fresh at ``now`` (:func:`~.rosmsg.judge_stamp`); JoyError (the shared
    :class:`~.rosmsg.Dropped`) when it is too large, not a Joy, stale, or holds too many
    or non-finite values."""
    if len(data) > MAX_JOY_BYTES:
        raise JoyError("too_large", f"{len(data)} bytes > {MAX_JOY_BYTES}")
    try:
        m: Any = STORE.deserialize_cdr(data, JOY)
    except Exception as e:  # rosbags raises SerdeError, struct and index errors
        raise JoyError("bad_cdr", str(e)[:80]) from None
    axes, buttons = rosmsg.joy_values(m)
    return rosmsg.judge_stamp(m.header, now, timeout), axes, buttons


# --- a node ------------------------------------------------------------------------------

class RosPublisher:
    """One ROS topic published through rmw_zenoh's key, with its token and attachment."""

    def __init__(self, node: RosNode, topic: str, type_name: str, entity_id: int):
        self.topic, self.type_name = topic, type_name
        self.key = data_key(node.domain, topic, type_name)
        self.token_key = node.token(entity_id, PUBLISHER, topic, type_name)
        self.gid = gid(self.token_key)
        self.seq = 0  # the last sequence number sent (rmw_zenoh starts at 1)
        self._pub = node.session.declare_publisher(
            self.key, encoding=CDR, congestion_control=zenoh.CongestionControl.DROP)
        self._token = node.session.liveliness().declare_token(self.token_key)

    def put(self, payload: bytes) -> None:
        self.seq += 1
        self._pub.put(payload, attachment=attachment(self.seq, time.time_ns(), self.gid))

    def close(self) -> None:
        self._token.undeclare()
        self._pub.undeclare()


class RosSubscription:
    """One ROS topic subscribed through rmw_zenoh's key (with its ``MS`` token);
    ``callback(payload)`` runs on Zenoh's thread."""

    def __init__(self, node: RosNode, topic: str, type_name: str, entity_id: int,
                 callback: Callable[[bytes], None]):
        self.key = data_key(node.domain, topic, type_name)
        self.token_key = node.token(entity_id, SUBSCRIPTION, topic, type_name)
        self._sub = node.session.declare_subscriber(
            self.key, lambda s: callback(s.payload.to_bytes()))
        self._token = node.session.liveliness().declare_token(self.token_key)

    def close(self) -> None:
        self._token.undeclare()
        self._sub.undeclare()


class RosNode:
    """A ROS 2 node ``name`` in ``namespace`` on ROS domain ``domain``, as rmw_zenoh
    announces one; its publishers and subscriptions are closed with it."""

    def __init__(self, session: zenoh.Session, name: str, namespace: str = "/sctd",
                 domain: int = 0):
        if not 0 <= domain <= 232:  # what rmw accepts (DDS port arithmetic)
            raise RosError(f"--ros-domain {domain}: expected 0 to 232")
        self.session, self.name, self.domain = session, name, domain
        self.namespace = check_namespace(namespace)
        self.zid = str(session.info.zid())
        self._ids = itertools.count()
        self.node_id = next(self._ids)
        self.token_key = self.token(self.node_id, NODE)
        self._entities: list[Any] = [session.liveliness().declare_token(self.token_key)]

    def token(self, entity_id: int, kind: str, topic: str | None = None,
              type_name: str | None = None) -> str:
        return liveliness_token(self.domain, self.zid, self.node_id, entity_id, kind,
                                self.namespace, self.name, topic, type_name)

    def topic(self, name: str) -> str:
        return topic_name(self.namespace, name)

    def publisher(self, name: str, type_name: str) -> RosPublisher:
        p = RosPublisher(self, self.topic(name), type_name, next(self._ids))
        self._entities.append(p)
        return p

    def subscribe(self, name: str, type_name: str, callback: Callable[[bytes], None]) -> RosSubscription:
        s = RosSubscription(self, self.topic(name), type_name, next(self._ids), callback)
        self._entities.append(s)
        return s

    def close(self) -> None:
        for e in reversed(self._entities):
            if isinstance(e, zenoh.LivelinessToken):
                e.undeclare()
            else:
                e.close()
        self._entities.clear()

    def __enter__(self) -> RosNode:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class PoseOut:
    """A pose topic at most ``rate`` Hz: :meth:`offer` drops what comes sooner. Called
    from one thread (the daemon's publisher thread, the simulator's loop)."""

    def __init__(self, publisher: RosPublisher, rate: float):
        if not rate > 0:
            raise RosError(f"--ros-rate {rate}: must be > 0")
        self.publisher = publisher
        self.period = 1.0 / rate
        self._next = 0.0
        self.sent = 0

    def offer(self, stamp: float, pose: Sequence[float]) -> bool:
        now = time.monotonic()
        if now < self._next:
            return False
        # on the period's cadence; after a pause, a period from now (no burst)
        cadence = self._next + self.period
        self._next = cadence if cadence > now else now + self.period
        self.publisher.put(encode_pose_stamped(stamp, pose))
        self.sent += 1
        return True


class JoyIn:
    """``sensor_msgs/msg/Joy`` on ``<namespace>/joy`` decoded in the subscriber's
    callback and handed to ``on_joy(stamp, axes, buttons)``, the stamp its header's;
    malformed or stale ones (older or further ahead than ``timeout``, or stamped zero)
    are dropped and counted by reason (:attr:`dropped`)."""

    def __init__(self, node: RosNode, on_joy: Callable[[float, tuple[float, ...], tuple[int, ...]], None],
                 timeout: float, name: str = "joy"):
        self.on_joy, self.timeout = on_joy, timeout
        self.received = 0
        self.dropped: Counter[str] = Counter()
        self._lock = threading.Lock()  # Zenoh may call back from more than one thread
        self.subscription = node.subscribe(name, JOY, self._on_payload)

    def _on_payload(self, data: bytes) -> None:
        with self._lock:
            try:
                stamp, axes, buttons = decode_joy(data, time.time(), self.timeout)
            except JoyError as e:
                self.dropped[e.reason] += 1
                return
            self.received += 1
            self.on_joy(stamp, axes, buttons)


JoyMap = Callable[[tuple[float, ...], tuple[int, ...]], tuple[list[float], list[int], bool]]


class RuntimeRos:
    """What ``sctd run --ros`` adds to the daemon: node ``sctd_run`` publishing the
    target on ``<namespace>/target_pose`` (at most ``rate`` Hz, from the daemon's
    publisher thread through :meth:`target`) and taking ``<namespace>/joy``: each Joy is
    mapped by ``joy_map`` to ``u`` and ``[mode, enable, escape]`` and put as an sctd
    input message on ``input_key``, stamped with its header's stamp (one older than
    ``timeout``, the daemon's input timeout, is dropped), where the daemon's input ring
    takes it like any device's."""

    def __init__(self, session: zenoh.Session, input_key: str, joy_map: JoyMap,
                 namespace: str = "/sctd", domain: int = 0, rate: float = 100.0,
                 timeout: float = 0.1):
        self.joy_map = joy_map
        self.input_key = input_key
        self.node = RosNode(session, "sctd_run", namespace, domain)
        try:
            self.target_pose = PoseOut(self.node.publisher("target_pose", POSE_STAMPED), rate)
            self._input = session.declare_publisher(input_key, encoding=MSGPACK,
                                                    congestion_control=zenoh.CongestionControl.DROP)
            self._seq = 0
            self.joy = JoyIn(self.node, self._on_joy, timeout)
        except BaseException:
            self.node.close()
            raise

    def _on_joy(self, stamp: float, axes: tuple[float, ...], buttons: tuple[int, ...]) -> None:
        u, roles, stop = self.joy_map(axes, buttons)
        self._seq += 1
        self._input.put(codec.encode_input(self._seq, stamp, u, roles, stop))

    def target(self, stamp: float, pose: Sequence[float]) -> None:
        self.target_pose.offer(stamp, pose)

    def stats(self) -> dict[str, Any]:
        """For the daemon's status: poses sent, Joy messages taken and dropped."""
        return {"target_pose_sent": self.target_pose.sent, "joy_received": self.joy.received,
                "joy_dropped": dict(self.joy.dropped)}

    def close(self) -> None:
        self.node.close()
        self._input.undeclare()

    def __enter__(self) -> RuntimeRos:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SimRos:
    """What ``sctd sim --ros`` adds: node ``sctd_sim`` publishing the measured end
    effector on ``<namespace>/ee_pose`` at most ``rate`` Hz (:meth:`ee`, from the
    simulator's loop: one CDR encoding and put per ROS message)."""

    def __init__(self, session: zenoh.Session, namespace: str = "/sctd", domain: int = 0,
                 rate: float = 100.0):
        self.node = RosNode(session, "sctd_sim", namespace, domain)
        try:
            self.ee_pose = PoseOut(self.node.publisher("ee_pose", POSE_STAMPED), rate)
        except BaseException:
            self.node.close()
            raise

    def ee(self, stamp: float, pose: Sequence[float]) -> None:
        self.ee_pose.offer(stamp, pose)

    def close(self) -> None:
        self.node.close()

    def __enter__(self) -> SimRos:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
