"""ROS 2 messages as sctd reads them, for both of its ROS paths (``docs/ros2.md``): the
rmw_zenoh path (``sctd run --ros``: rosbags' message classes) and the ROS 2 node
(``sctd ros``: rclpy's). Both kinds of message have the fields of the ROS message
definitions under the same names, so the checks here are written once, on those fields,
and neither library is imported: a message goes in, sctd's plain values come out, or
:class:`Dropped` names why the message is not used (its counter's name).

What a message must be to be used (the same on both paths):

- **stamp** (``header.stamp``) is sctd's ``stamp``. Zero (a driver that never sets it),
  older than ``timeout`` or more than ``timeout`` ahead of this machine's clock: dropped
  (``zero_stamp``, ``stale_stamp``, ``future_stamp``); the daemon's own check, which
  judges sctd's stamps the same way, would refuse it anyway.
- **frame** (``header.frame_id``) is the configured world frame, or the message is
  dropped (``wrong_frame``): there are no tf2 wheels, and a pose in another frame is
  not guessed at.
- **poses**: finite, a quaternion of norm within 1 % of one (normalised), a position
  within the wire's limit (``nonfinite``, ``bad_quaternion``, ``far``).
- **Joy**: at most :data:`MAX_VALUES` axes and buttons (``too_many``), finite axes
  (``nonfinite``); buttons 0/1.
- **JointState**: the named joints found, finite (``missing_joint``, ``nonfinite``).

No clock is read here: ``now`` is passed in.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from .codec import MAX_POSITION

MAX_VALUES = 64  # axes or buttons in one Joy, joints in one JointState
QUATERNION_TOLERANCE = 1e-2  # |norm - 1| a pose may have (the wire's own)


class Dropped(ValueError):
    """A ROS message that is not used; ``reason`` is its drop counter's name."""

    def __init__(self, reason: str, detail: str = ""):
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


def stamp_of(header: Any) -> float:
    """``header.stamp`` in seconds (Unix time for a ROS clock)."""
    return float(header.stamp.sec) + float(header.stamp.nanosec) * 1e-9


def time_fields(stamp: float) -> tuple[int, int]:
    """``(sec, nanosec)`` of ``builtin_interfaces/msg/Time`` for ``stamp`` (s); ValueError
    outside its int32 seconds."""
    if not -2**31 <= stamp < 2**31 - 1:
        raise ValueError(f"stamp {stamp!r}: outside ROS Time's int32 seconds")
    sec = math.floor(stamp)
    return sec, min(round((stamp - sec) * 1e9), 999_999_999)


def judge_stamp(header: Any, now: float, timeout: float) -> float:
    """The message's stamp, if it is fresh at ``now`` (s, the same clock): not zero, not
    older than ``timeout``, not more than ``timeout`` ahead; else :class:`Dropped`."""
    if header.stamp.sec == 0 and header.stamp.nanosec == 0:
        raise Dropped("zero_stamp")
    stamp = stamp_of(header)
    if now - stamp > timeout:
        raise Dropped("stale_stamp", f"{now - stamp:.3f} s old")
    if stamp - now > timeout:
        raise Dropped("future_stamp", f"{stamp - now:.3f} s ahead")
    return stamp


def check_frame(header: Any, frame: str) -> None:
    """:class:`Dropped` (``wrong_frame``) unless ``header.frame_id`` is ``frame``."""
    if header.frame_id != frame:
        raise Dropped("wrong_frame", f"{str(header.frame_id)[:40]!r}, not {frame!r}")


def pose_of(pose: Any) -> list[float]:
    """``[x, y, z, qx, qy, qz, qw]`` of a ``geometry_msgs/msg/Pose`` (the quaternion
    normalised), or :class:`Dropped`."""
    p, q = pose.position, pose.orientation
    v = [float(p.x), float(p.y), float(p.z), float(q.x), float(q.y), float(q.z), float(q.w)]
    if not math.isfinite(sum(v)):
        raise Dropped("nonfinite")
    n = math.sqrt(v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6])
    if abs(n - 1.0) > QUATERNION_TOLERANCE:
        raise Dropped("bad_quaternion", f"norm {n:.4f}")
    if max(abs(v[0]), abs(v[1]), abs(v[2])) > MAX_POSITION:
        raise Dropped("far", f"position beyond {MAX_POSITION:g} m")
    return [*v[:3], v[3] / n, v[4] / n, v[5] / n, v[6] / n]


def stamped_pose(msg: Any, now: float, timeout: float, frame: str) -> tuple[float, list[float]]:
    """``(stamp, pose)`` of a ``geometry_msgs/msg/PoseStamped`` in ``frame``, fresh at
    ``now``; or :class:`Dropped`."""
    check_frame(msg.header, frame)
    stamp = judge_stamp(msg.header, now, timeout)
    return stamp, pose_of(msg.pose)


def joy_values(msg: Any) -> tuple[tuple[float, ...], tuple[int, ...]]:
    """``(axes, buttons)`` of a ``sensor_msgs/msg/Joy``, or :class:`Dropped`."""
    if len(msg.axes) > MAX_VALUES or len(msg.buttons) > MAX_VALUES:
        raise Dropped("too_many", f"{len(msg.axes)} axes, {len(msg.buttons)} buttons")
    axes = tuple(float(a) for a in msg.axes)
    if not math.isfinite(sum(axes)):
        raise Dropped("nonfinite", "an axis is not finite")
    return axes, tuple(1 if b else 0 for b in msg.buttons)


def joint_positions(msg: Any, names: Sequence[str]) -> list[float]:
    """The positions of the joints ``names`` (in that order) in a
    ``sensor_msgs/msg/JointState``, or :class:`Dropped`."""
    if len(msg.name) > MAX_VALUES or len(msg.position) != len(msg.name):
        raise Dropped("bad_joints", f"{len(msg.name)} names, {len(msg.position)} positions")
    at = {str(n): i for i, n in enumerate(msg.name)}
    missing = [n for n in names if n not in at]
    if missing:
        raise Dropped("missing_joint", ", ".join(missing)[:80])
    q = [float(msg.position[at[n]]) for n in names]
    if not math.isfinite(sum(q)):
        raise Dropped("nonfinite")
    return q
