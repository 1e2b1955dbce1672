"""The ROS 2 side of ``sctd bench ros`` (``python -m sctd_services.ros2.probe MODE``),
run inside the bench's network namespace:

- ``echo``: republishes every ``PoseStamped`` of ``ping`` on ``pong``, until stopped;
- ``ping``: a bare rclpy round trip: ``PoseStamped`` on ``ping`` at ``--rate`` Hz, each
  stamped when sent; the time until it comes back on ``pong`` (ms, p50/p99/max, JSON);
- ``joy``: a person's push through ``sctd ros``: ``Joy`` at ``--rate`` Hz, centred, then
  pushed (deadman held) until the target (``sctd/target_pose``) moves, ``--steps``
  times after warming up (pushes until one moves the target: the daemon's first input,
  and the node matching this publisher, took 0.2-1 s), pushing one way then the other;
  the time from the first pushed Joy to the first target that moved (ms, JSON; a push
  that moved nothing in 2 s is left out: ``n`` says how many did);
- ``idle``: the node's floor: an rclpy node spinning a single-threaded executor, with a
  Zenoh session open on ``--connect`` (subscribed to nothing), until stopped; the bench
  takes its CPU beside ``sctd ros``'s, over the same seconds.

Times are this process's clock (``time.perf_counter``): both ends of each figure are
here.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
import time

import numpy as np


def _summary(ms: list[float]) -> dict[str, float | int]:
    a = np.asarray(ms)
    if not len(a):
        return {"n": 0}
    return {"n": len(a), "p50": round(float(np.percentile(a, 50)), 3),
            "p99": round(float(np.percentile(a, 99)), 3), "max": round(float(a.max()), 3)}


def echo(node, stop: threading.Event) -> None:
    from geometry_msgs.msg import PoseStamped

    pub = node.create_publisher(PoseStamped, "pong", 10)
    node.create_subscription(PoseStamped, "ping", pub.publish, 10)


def ping(node, executor, n: int, rate: float) -> dict:
    from geometry_msgs.msg import PoseStamped

    sent: dict[int, float] = {}
    got: list[float] = []

    def on_pong(m) -> None:
        t0 = sent.pop(m.header.stamp.nanosec, None)
        if t0 is not None:
            got.append((time.perf_counter() - t0) * 1e3)
    pub = node.create_publisher(PoseStamped, "ping", 10)
    node.create_subscription(PoseStamped, "pong", on_pong, 10)
    _settle(executor, lambda: pub.get_subscription_count() > 0, 20.0)
    _spin(executor, 1.0)  # the echo's way back is matched too
    for k in range(n):
        m = PoseStamped()
        m.header.stamp.nanosec = k
        sent[k] = time.perf_counter()
        pub.publish(m)
        _spin(executor, 1.0 / rate)
    _spin(executor, 0.5)
    return {"round_trip_ms": _summary(got), "lost": len(sent)}


def joy(node, executor, steps: int, rate: float) -> dict:
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import Joy

    last: list = [None, 0.0]  # newest target position, when it arrived

    def on_target(m) -> None:
        p = m.pose.position
        last[0], last[1] = (p.x, p.y, p.z), time.perf_counter()
    pub = node.create_publisher(Joy, "joy", 10)
    node.create_subscription(PoseStamped, "sctd/target_pose", on_target, 10)

    def send(u: float) -> None:
        m = Joy()
        t = time.time()
        m.header.stamp.sec, m.header.stamp.nanosec = int(t), int((t - int(t)) * 1e9)
        # as the joy package's game_controller_node numbers a pad (sctd ros's default map):
        # the left stick's x is axis 0, the right shoulder (button 10) the deadman
        m.axes, m.buttons = [u, 0.0, 0.0, 0.0, 0.0, 0.0], [0] * 10 + [1]
        pub.publish(m)
    _settle(executor, lambda: last[0] is not None and pub.get_subscription_count() > 0, 30.0)
    def push(k: int) -> float | None:
        """Centre, then push until the target moves: ms from the first pushed Joy, or
        None. (On a loaded machine the daemon may hold and re-seed, and a re-seed's jump
        would count: the bench is meant for a quiet one.)"""
        end = time.perf_counter() + 0.4
        while time.perf_counter() < end:  # centred: the target comes to rest
            send(0.0)
            _spin(executor, 1.0 / rate)
        rest, t0 = last[0], time.perf_counter()
        sign = 1.0 if k % 2 == 0 else -1.0
        while time.perf_counter() - t0 < 2.0:
            send(0.8 * sign)
            _spin(executor, 1.0 / rate)
            if last[0] != rest and last[1] > t0:
                return (last[1] - t0) * 1e3
        return None
    # warm up until a push moves the target: the node may match this publisher after this
    # publisher matched it, and the daemon's first input starts it
    warm = time.perf_counter() + 60.0
    while push(1) is None:
        if time.perf_counter() > warm:
            raise SystemExit("no push moved the target in 60 s")
    print(json.dumps({"measuring": True}), flush=True)  # (the bench's CPU figures start here)
    got = [ms for ms in (push(k) for k in range(steps)) if ms is not None]
    return {"joy_to_target_ms": _summary(got), "steps": steps, "each_ms": [round(x, 1) for x in got]}


def _serve_until(stop: threading.Event, executor, connect: list[str] | None,
                 follow: str | None = None) -> None:
    """Spin as ``sctd ros`` does (with a Zenoh session on ``connect`` unless None) until
    ``stop``; with ``follow``, the session also subscribes that key into a ring of one
    that nothing reads (what receiving the stream costs, before anything is done with it)."""
    from contextlib import nullcontext

    from sctd.wire.session import session

    with session(connect=connect) if connect is not None else nullcontext() as s:
        sub = None
        if follow is not None and s is not None:
            import zenoh

            sub = s.declare_subscriber(follow, zenoh.handlers.RingChannel(1))
        print(json.dumps({"ready": True}), flush=True)
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)
        if sub is not None:
            sub.undeclare()


def _spin(executor, seconds: float) -> None:
    end = time.perf_counter() + seconds
    while True:
        left = end - time.perf_counter()
        if left <= 0:
            return
        executor.spin_once(timeout_sec=left)


def _settle(executor, ready, timeout: float) -> None:
    end = time.perf_counter() + timeout
    while not ready():
        if time.perf_counter() > end:
            raise SystemExit("the other side never appeared")
        _spin(executor, 0.05)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sctd_services.ros2.probe")
    p.add_argument("mode", choices=("echo", "ping", "joy", "idle"))
    p.add_argument("--n", type=int, default=500, help="ping: round trips")
    p.add_argument("--steps", type=int, default=40, help="joy: pushes")
    p.add_argument("--rate", type=float, default=100.0, help="Hz of ping or Joy")
    p.add_argument("--connect", action="append", default=[], metavar="ENDPOINT", help="idle: Zenoh endpoint")
    p.add_argument("--follow", metavar="KEY", help="idle: also subscribe this Zenoh key (nothing reads it)")
    args = p.parse_args(argv)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    rclpy.init()
    node = rclpy.create_node(f"bench_{args.mode}")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        if args.mode in ("echo", "idle"):
            if args.mode == "echo":
                echo(node, stop)
            _serve_until(stop, executor, args.connect if args.mode == "idle" else None, args.follow)
            return 0
        out = ping(node, executor, args.n, args.rate) if args.mode == "ping" else \
            joy(node, executor, args.steps, args.rate)
        print(json.dumps(out), flush=True)
        return 0
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
