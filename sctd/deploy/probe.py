"""The Zenoh probe that runs inside a host's namespace:
``python -m sctd.deploy.probe listen|record|put|query|echo|ping ...``.

Each command opens a session from a Zenoh config file (``--config``: the role the probe
plays) and prints JSON lines: ``{"ready": true}`` once its declarations are in place
where others wait for that, and its result last. A session the router refuses is a
result too (``refused``), not a crash: an intruder's probe reports what it got. See
:func:`main`.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time

import msgpack
import zenoh

from sctd.timing import wait_until
from sctd.wire.session import MSGPACK, TEXT, make_config


class _Refused(Exception):
    """The session could not be opened (the router refused or is not there)."""


def _open(config: str) -> zenoh.Session:
    try:
        return zenoh.open(zenoh.Config.from_file(config))
    except zenoh.ZError as e:
        raise _Refused(str(e)) from None


def listen_main(args: argparse.Namespace) -> int:
    """Count the samples arriving on each key expression for ``--seconds``, and the Unix
    time of the first one per key. With ``--mark NAME`` only msgpack maps that have the
    field NAME count, per value of that field (``marked``: value -> key -> count)."""
    counts = {k: 0 for k in args.key}
    marked: dict[str, dict[str, int]] = {}
    first: dict[str, float] = {}
    lock = threading.Lock()
    try:
        s = _open(args.config)
    except _Refused as e:
        print(json.dumps({"ready": True, "refused": str(e)}), flush=True)
        print(json.dumps({"counts": counts, "marked": marked, "first": first, "refused": str(e)}))
        return 0
    subs = []
    for key in args.key:
        def on(sample: zenoh.Sample, key: str = key) -> None:
            mark = None
            if args.mark is not None:
                try:
                    msg = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
                except (ValueError, msgpack.UnpackException):
                    return
                if not isinstance(msg, dict) or args.mark not in msg:
                    return
                mark = str(msg[args.mark])
            with lock:
                counts[key] += 1
                first.setdefault(key, time.time())
                if mark is not None:
                    per_key = marked.setdefault(mark, {})
                    per_key[key] = per_key.get(key, 0) + 1
        subs.append(s.declare_subscriber(key, on))
    print(json.dumps({"ready": True}), flush=True)
    stop = threading.Event()
    wait_until(stop, args.seconds)
    for sub in subs:
        sub.undeclare()
    s.close()
    with lock:
        print(json.dumps({"counts": counts, "marked": marked, "first": first}), flush=True)
    return 0


def record_main(args: argparse.Namespace) -> int:
    """Write every sample on ``--key`` to ``--out`` as JSON lines ``{"key", "t",
    "msg"}`` (``t``: arrival, Unix time; ``msg``: the msgpack map, only ``--field``
    fields if given), until SIGTERM."""
    fields = set(args.field or ())
    lock = threading.Lock()
    out = open(args.out, "a", buffering=1)

    def on(sample: zenoh.Sample) -> None:
        t = time.time()
        try:
            msg = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
        except (ValueError, msgpack.UnpackException):
            msg = None
        if isinstance(msg, dict) and fields:
            msg = {k: v for k, v in msg.items() if k in fields}
        line = json.dumps({"key": str(sample.key_expr), "t": t, "msg": msg}, default=repr)
        with lock:
            out.write(line + "\n")

    stop = threading.Event()
    limits = [(key, args.max_rate) for key in args.key] if args.max_rate else []
    s = zenoh.open(make_config(config_file=args.config, rate_limits=limits))
    subs = [s.declare_subscriber(key, on) for key in args.key]
    wait_until(stop)
    for sub in subs:
        sub.undeclare()
    s.close()
    with lock:
        out.close()
    return 0


class _PayloadFile:
    """``--payload-file``: the payload as JSON in a file, read again whenever the file
    changes, so that whoever started the probe (outside its namespace: the file system is
    shared) changes what a running sender sends without a new sender (a new seq)."""

    def __init__(self, path: str):
        self.path, self.mtime = path, -1
        self.payload: dict = {}

    def get(self) -> dict:
        try:
            mtime = os.stat(self.path).st_mtime_ns
            if mtime != self.mtime:
                with open(self.path) as f:
                    self.payload = json.load(f)
                self.mtime = mtime
        except (OSError, ValueError):
            pass  # replaced mid-read: the last payload until the next message
        return self.payload


def put_main(args: argparse.Namespace) -> int:
    """Put ``--n`` msgpack maps (``--payload`` JSON, or ``--payload-file``'s) on each
    ``--key``, ``--rate`` Hz."""
    sent = {k: 0 for k in args.key}
    try:
        s = _open(args.config)
    except _Refused as e:
        print(json.dumps({"sent": sent, "tried": args.n * len(args.key), "refused": str(e)}))
        return 0
    time.sleep(args.settle)  # let the declarations of the others reach this session
    payload = json.loads(args.payload)
    changing = _PayloadFile(args.payload_file) if args.payload_file else None
    block = zenoh.CongestionControl.BLOCK
    for i in range(args.n):
        if changing is not None:
            payload = changing.get()
        for key in args.key:
            msg = dict(payload, seq=i, stamp=time.time())
            # blocking, not dropped when a queue is full: the count must be what was sent
            s.put(key, msgpack.packb(msg, use_bin_type=True), congestion_control=block, encoding=MSGPACK)
            sent[key] += 1
        time.sleep(1.0 / args.rate)
    time.sleep(0.3)
    s.close()
    print(json.dumps({"sent": sent, "tried": args.n * len(args.key)}), flush=True)
    return 0


def query_main(args: argparse.Namespace) -> int:
    """One query on ``--key`` (msgpack ``--payload`` JSON, if any); how many ok and
    error replies arrived."""
    try:
        s = _open(args.config)
    except _Refused as e:
        print(json.dumps({"ok": 0, "err": 0, "refused": str(e)}))
        return 0
    time.sleep(args.settle)
    kw = {} if args.payload is None else {"payload": msgpack.packb(json.loads(args.payload),
                                                                    use_bin_type=True)}
    ok = err = 0
    for reply in s.get(args.key, timeout=args.timeout, **kw):
        if reply.ok is not None:
            ok += 1
        else:
            err += 1
    s.close()
    print(json.dumps({"ok": ok, "err": err}), flush=True)
    return 0


# The echo runs on keys the roles may use, so it takes the same path through the router's
# access control as input and target: the input role publishes ``input/**``, the runtime
# role subscribes to it and publishes ``target``, which the input role may read. The robot
# name ``echo`` keeps it apart from the robot's own keys.
ECHO_PING = "sctd/echo/input/ping"
ECHO_PONG = "sctd/echo/target"


def echo_main(args: argparse.Namespace) -> int:
    """Republish every ``ECHO_PING`` sample on ``ECHO_PONG`` until SIGTERM (run it in the
    runtime's role)."""
    stop = threading.Event()
    with _open(args.config) as s, s.declare_publisher(ECHO_PONG, express=True, encoding=TEXT) as pub, \
            s.declare_subscriber(ECHO_PING, lambda sample: pub.put(sample.payload.to_bytes())):
        print(json.dumps({"ready": True}), flush=True)
        wait_until(stop)
    return 0


def ping_main(args: argparse.Namespace) -> int:
    """Ping the echo ``--n`` times at ``--rate`` Hz (in the input's role); the round-trip
    summary (ms) after ``--warmup`` pings."""
    from sctd.timing import RoundTrips, Ticker
    trips = RoundTrips()
    with _open(args.config) as s, \
            s.declare_subscriber(ECHO_PONG, lambda sample: trips.answered(
                int(sample.payload.to_bytes()), time.monotonic())), \
            s.declare_publisher(ECHO_PING, express=True, encoding=TEXT) as pub:
        time.sleep(args.settle)
        ticker = Ticker(1.0 / args.rate, spin=0.0)
        for seq in range(args.n):
            ticker.wait()
            trips.counting = seq >= args.warmup
            trips.sent(seq)
            pub.put(str(seq).encode())
        time.sleep(0.3)
    print(json.dumps({"echo_rtt_ms": trips.histogram.summary_ms(), "pongs": trips.answers}), flush=True)
    return 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m sctd.deploy.probe",
                                description="Zenoh probes run inside a host's namespace")
    sub = p.add_subparsers(dest="cmd", required=True)
    lis = sub.add_parser("listen", help="count samples per key")
    lis.add_argument("--config", required=True)
    lis.add_argument("--key", action="append", required=True)
    lis.add_argument("--seconds", type=float, default=5.0)
    lis.add_argument("--mark", default=None, help="count only msgpack maps with this field")
    lis.set_defaults(func=listen_main)
    rec = sub.add_parser("record", help="samples on keys to a JSON-lines file until SIGTERM")
    rec.add_argument("--config", required=True)
    rec.add_argument("--key", action="append", required=True)
    rec.add_argument("--field", action="append", help="keep only these fields (repeatable)")
    rec.add_argument("--out", required=True)
    rec.add_argument("--max-rate", type=float, default=None,
                     help="Hz: take at most this many samples per second of each key (Zenoh's "
                          "downsampling, on arrival)")
    rec.set_defaults(func=record_main)
    put = sub.add_parser("put", help="put msgpack maps on keys")
    put.add_argument("--config", required=True)
    put.add_argument("--key", action="append", required=True)
    put.add_argument("--n", type=int, default=10)
    put.add_argument("--rate", type=float, default=50.0)
    put.add_argument("--settle", type=float, default=1.0)
    put.add_argument("--payload", default="{}")
    put.add_argument("--payload-file", default=None,
                     help="JSON payload read again whenever the file changes (instead of --payload)")
    put.set_defaults(func=put_main)
    q = sub.add_parser("query", help="one query, count replies")
    q.add_argument("--config", required=True)
    q.add_argument("--key", required=True)
    q.add_argument("--payload", default=None)
    q.add_argument("--timeout", type=float, default=3.0)
    q.add_argument("--settle", type=float, default=1.0)
    q.set_defaults(func=query_main)
    e = sub.add_parser("echo", help=f"republish {ECHO_PING} on {ECHO_PONG} until SIGTERM")
    e.add_argument("--config", required=True)
    e.set_defaults(func=echo_main)
    pg = sub.add_parser("ping", help="round trips to the echo")
    pg.add_argument("--config", required=True)
    pg.add_argument("--n", type=int, default=5000)
    pg.add_argument("--rate", type=float, default=500.0)
    pg.add_argument("--warmup", type=int, default=500)
    pg.add_argument("--settle", type=float, default=1.0)
    pg.set_defaults(func=ping_main)
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
