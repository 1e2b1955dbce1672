"""The ``--ros`` flags of ``sctd run`` and ``sctd sim`` (docs/ros2.md), defined once and
without loading rosbags: :mod:`sctd.wire.ros` is imported only when ``--ros`` is given."""

from __future__ import annotations

import argparse


def add_ros_arguments(p: argparse.ArgumentParser, what: str) -> None:
    """``--ros``, ``--ros-domain``, ``--ros-namespace``, ``--ros-rate``; ``what`` says
    what the program publishes and takes."""
    g = p.add_argument_group("ROS 2 over rmw_zenoh (docs/ros2.md; needs the ros extra)")
    g.add_argument("--ros", action="store_true", help=f"be a ROS 2 (Jazzy, rmw_zenoh) node: {what}")
    g.add_argument("--ros-domain", type=int, default=0, help="ROS domain id (default %(default)s)")
    g.add_argument("--ros-namespace", default="/sctd",
                   help="namespace of the node and its topics (default %(default)s)")
    g.add_argument("--ros-rate", type=float, default=100.0,
                   help="most pose messages per second on ROS (default %(default)s)")


def check_namespace(ns: str) -> str:
    """A ROS namespace (``/``-separated names of letters, digits and ``_``, not starting
    with a digit), normalized to a leading ``/`` and no trailing one; ValueError naming
    the flag otherwise."""
    ns = "/" + ns.strip("/")
    for part in ns.split("/")[1:]:
        if part and not (part.replace("_", "a").isalnum() and part.isascii() and not part[0].isdigit()):
            raise ValueError(f"--ros-namespace {ns!r}: {part!r} is not a ROS name "
                             "(letters, digits and _, not starting with a digit)")
    return ns


def check_ros_arguments(args: argparse.Namespace) -> None:
    """With ``--ros``: the ROS flags in range and the ros extra installed; ValueError
    naming the flag otherwise."""
    if not args.ros:
        return
    if not 0 <= args.ros_domain <= 232:
        raise ValueError(f"--ros-domain {args.ros_domain}: expected 0 to 232")
    if not args.ros_rate > 0:
        raise ValueError(f"--ros-rate {args.ros_rate}: must be > 0")
    check_namespace(args.ros_namespace)
    try:
        import rosbags  # noqa: F401
        import xxhash  # noqa: F401
    except ImportError as e:
        raise ValueError(f"--ros needs the ros extra (pip install 'sctd[ros]'): {e}") from None
