"""``sctd echo KEY`` and ``sctd hz KEY``: what ``ros2 topic echo`` and ``ros2 topic hz``
are to ROS, for the wire contract (docs/wire-contract.md).

Zenoh's own example clients print payloads as text; the contract's are msgpack. ``echo``
decodes any sample on ``KEY`` (a key expression, wildcards allowed; one without the
``sctd/`` prefix is taken under ``sctd/<robot>/``) and prints it: its key, its declared
encoding and its value (msgpack decoded, byte strings shown by their length, anything
else as text or hex). ``hz`` prints, once a second, each key's rate and the spread of
the intervals between its samples over a sliding window.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from collections import deque
from typing import Any

import msgpack
import zenoh

from ..app.errors import EXIT_OK
from ..app.options import add_robot_argument
from ..timing import wait_until
from ..wire import Keys
from ..wire.session import add_zenoh_arguments, session_from_args


def full_key(key: str, robot: str) -> str:
    """``KEY`` as given when it starts with ``sctd/`` (or is a bare wildcard), else under
    the robot's prefix: ``target`` -> ``sctd/edan/target``."""
    if key.startswith("sctd/") or key in ("**", "*"):
        return key
    return f"{Keys(robot).prefix}/{key.lstrip('/')}"


def plain(value: Any) -> Any:
    """A decoded msgpack value as JSON-able data: byte strings as ``{"bytes": n}``, map
    keys as strings, non-finite floats as strings."""
    if isinstance(value, bytes | bytearray | memoryview):
        return {"bytes": len(value)}
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def decode(data: bytes, encoding: str = "") -> tuple[str, Any]:
    """``("msgpack", value)`` for a msgpack payload (one whole object), ``("text", str)``
    for UTF-8, else ``("bytes", {"bytes": n, "head": hex of the first 32})``. A declared
    ``text/*`` encoding is taken as text first (the digits of a ping are also a msgpack
    integer); any other, or none, as msgpack first."""
    def as_text() -> tuple[str, Any] | None:
        try:
            return "text", data.decode("utf-8")
        except UnicodeDecodeError:
            return None

    if encoding.startswith("text/") and (t := as_text()) is not None:
        return t
    try:
        return "msgpack", plain(msgpack.unpackb(data, raw=False, strict_map_key=False))
    except Exception:  # msgpack raises several unrelated types on bad bytes
        pass
    return as_text() or ("bytes", {"bytes": len(data), "head": data[:32].hex()})


def describe(sample: zenoh.Sample, now: float) -> dict[str, Any]:
    """One sample as plain data: key, declared encoding, arrival time, what it decoded as
    and its value."""
    encoding = str(sample.encoding)
    kind, value = decode(sample.payload.to_bytes(), encoding)
    return {"key": str(sample.key_expr), "encoding": encoding, "received": round(now, 6),
            "as": kind, "value": value}


def add_echo_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", metavar="KEY",
                        help="a key expression (wildcards allowed), e.g. sctd/edan/target, or one "
                             "under sctd/<robot>/: target, status, input/*, objects/**")
    add_robot_argument(parser)
    parser.add_argument("--json", action="store_true", help="one JSON object per sample and line")
    parser.add_argument("--count", type=int, default=0, help="stop after N samples (default: run)")
    parser.add_argument("--timeout", type=float, default=0.0,
                        help="stop after this many seconds (default: run until Ctrl-C)")
    add_zenoh_arguments(parser)


def add_hz_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", metavar="KEY", help="as for sctd echo")
    add_robot_argument(parser)
    parser.add_argument("--window", type=int, default=1000,
                        help="intervals per key the figures are over (default %(default)s)")
    parser.add_argument("--timeout", type=float, default=0.0,
                        help="stop after this many seconds (default: run until Ctrl-C)")
    parser.add_argument("--json", action="store_true", help="one JSON object per report and line")
    add_zenoh_arguments(parser)


def main_echo(args: argparse.Namespace) -> int:
    """``sctd echo``: print every sample on the key until --count, --timeout or Ctrl-C."""
    key = full_key(args.key, args.robot)
    done = threading.Event()
    lock = threading.Lock()
    seen = [0]

    def on_sample(sample: zenoh.Sample) -> None:
        d = describe(sample, time.time())
        with lock:
            if done.is_set():
                return
            if args.json:
                print(json.dumps(d), flush=True)
            else:
                print(f"--- {d['key']} ({d['encoding']}, {d['as']})\n"
                      f"{json.dumps(d['value'], indent=1)}", flush=True)
            seen[0] += 1
            if args.count and seen[0] >= args.count:
                done.set()

    with session_from_args(args) as s, s.declare_subscriber(key, on_sample):
        wait_until(done, args.timeout)
    return EXIT_OK


class Rates:
    """Arrival times per key: rate and interval statistics over the last ``window``."""

    def __init__(self, window: int):
        self.window = window
        self.times: dict[str, deque[float]] = {}

    def add(self, key: str, t: float) -> None:
        self.times.setdefault(key, deque(maxlen=self.window + 1)).append(t)

    def report(self) -> dict[str, dict[str, float]]:
        out = {}
        for key, ts in sorted(self.times.items()):
            if len(ts) < 2:
                continue
            dt = [b - a for a, b in zip(list(ts)[:-1], list(ts)[1:], strict=True)]
            mean = sum(dt) / len(dt)
            std = math.sqrt(sum((x - mean) ** 2 for x in dt) / len(dt))
            out[key] = {"rate_hz": 1.0 / mean if mean > 0 else math.inf, "min_s": min(dt),
                        "max_s": max(dt), "std_s": std, "window": len(dt)}
        return out


def main_hz(args: argparse.Namespace) -> int:
    """``sctd hz``: each key's rate once a second until --timeout or Ctrl-C."""
    key = full_key(args.key, args.robot)
    rates = Rates(max(1, args.window))
    lock = threading.Lock()
    done = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        now = time.monotonic()
        with lock:
            rates.add(str(sample.key_expr), now)

    def reporter() -> None:
        while not done.wait(1.0):
            with lock:
                r = rates.report()
            if args.json:
                print(json.dumps(r), flush=True)
                continue
            if not r:
                print(f"no samples on {key} yet", file=sys.stderr, flush=True)
            for k, v in r.items():
                print(f"{k}: average rate {v['rate_hz']:.3f} Hz  min {v['min_s']:.4f} s  max "
                      f"{v['max_s']:.4f} s  std dev {v['std_s']:.5f} s  window {v['window']}",
                      flush=True)

    with session_from_args(args) as s, s.declare_subscriber(key, on_sample):
        t = threading.Thread(target=reporter, daemon=True)
        t.start()
        wait_until(done, args.timeout)
        done.set()
        t.join(2.0)
    return EXIT_OK
