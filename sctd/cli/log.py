"""``sctd log --mcap FILE`` and ``sctd replay FILE``: logs people can open.

``log`` records every key of the wire contract a robot's programs publish (targets,
status, input, state, objects, scene) into an MCAP file (the ``mcap`` package): one
channel per key, each message transcoded from msgpack to JSON, with a JSON Schema per
kind of key, so Foxglove (and any MCAP reader) decodes it. ``log_time`` is when the
sample arrived, ``publish_time`` the sender's ``stamp`` when it has one.

``replay`` publishes a log's observation keys (state, objects, scene, status) again,
msgpack as the contract has them, with their original spacing divided by ``--speed``;
``target``, ``input`` and ``can`` only with ``--all``, and never while a live daemon or
robot answers on the same prefix: it refuses to start when one does, and stops when one
appears (a sample on a replayed key it did not send).
"""

from __future__ import annotations

import argparse
import json
import math
import queue
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from ..runtime import codec
from ..runtime.codec import DEFAULT_ROBOT, Keys
from ..runtime.zsession import MSGPACK, add_zenoh_arguments, session_from_args
from .echo import decode, wait_until
from .errors import EXIT_FAILED, EXIT_OK, fail

OBSERVATIONS = ("state", "objects", "scene", "status")  # replayed by default
COMMANDS = ("target", "input", "can")  # replayed only with --all
RECORDED = ("target", "status", "input", "state", "objects", "scene")

_NUM = {"type": "number"}
_INT = {"type": "integer"}
_POSE = {"type": "array", "items": _NUM, "minItems": 7, "maxItems": 7,
         "description": "x, y, z (m), qx, qy, qz, qw"}
_STAMPED = {"seq": _INT, "stamp": {"type": "number", "description": "sender's Unix time (s)"},
            "v": _INT}
SCHEMAS: dict[str, dict[str, Any]] = {
    "target": {"properties": {**_STAMPED, "pose": _POSE, "state": {"type": "string"},
                              "skill": {"type": "string"}, "in_seq": _INT,
                              "in_device": {"type": "string"},
                              "seed": {"type": "boolean", "description": "the measured pose: a (re-)seed"}},
               "required": ["seq", "stamp", "pose"]},
    "state": {"properties": {**_STAMPED, "pose": _POSE, "q": {"type": "array", "items": _NUM},
                             "dq": {"type": "array", "items": _NUM},
                             "wrench": {"type": "array", "items": _NUM}},
              "required": ["seq", "stamp", "pose"]},
    "objects": {"properties": {**_STAMPED, "pose": _POSE}, "required": ["seq", "stamp", "pose"]},
    "input": {"properties": {**_STAMPED, "u": {"type": "array", "items": _NUM},
                             "buttons": {"type": "array", "items": _INT},
                             "stop": {"type": "integer", "description": "1: halt every device's motion"}},
              "required": ["seq", "stamp", "u"]},
    "status": {"properties": {"state": {"type": "string"}, "mode": {"type": "string"},
                              "skill": {"type": "string"}, "counters": {"type": "object"}}},
    "scene": {"properties": {"scene": {"type": "string"}}},
}


def kind_of(key: str, prefix: str) -> str | None:
    """The contract's kind of ``key`` under ``prefix`` (``sctd/edan/objects/mug`` ->
    ``objects``), or None for one that is not a recorded kind."""
    if not key.startswith(prefix + "/"):
        return None
    head = key[len(prefix) + 1:].split("/", 1)[0]
    return head if head in RECORDED or head == "can" else None


def schema(kind: str) -> bytes:
    """The JSON Schema of one kind of key (extra fields allowed: the contract may grow)."""
    doc = {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": f"sctd {kind}",
           "type": "object", "additionalProperties": True, **SCHEMAS[kind]}
    return json.dumps(doc).encode()


def _jsonable(value: Any) -> Any:
    """Non-finite floats as null (JSON has none); everything else as decoded."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_jsonable(v) for v in value]
    return value


class McapLog:
    """An MCAP file being written: one schema per kind, one channel per key."""

    def __init__(self, path: Path):
        from mcap.writer import Writer

        self.fh = path.open("wb")
        self.writer = Writer(self.fh)
        self.writer.start(profile="", library="sctd log")
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        self.counts: dict[str, int] = {}
        self.undecodable = 0

    def add(self, key: str, kind: str, data: bytes, received: float) -> None:
        how, value = decode(data)
        if how != "msgpack" or not isinstance(value, dict):
            self.undecodable += 1  # not a contract message: counted, not written
            return
        if kind not in self.schemas:
            self.schemas[kind] = self.writer.register_schema(f"sctd.{kind}", "jsonschema", schema(kind))
        if key not in self.channels:
            self.channels[key] = self.writer.register_channel(key, "json", self.schemas[kind],
                                                              {"source_encoding": "application/msgpack"})
        stamp = value.get("stamp")
        published = stamp if isinstance(stamp, int | float) and math.isfinite(stamp) else received
        n = self.counts.get(key, 0)
        self.writer.add_message(self.channels[key], int(received * 1e9),
                                json.dumps(_jsonable(value)).encode(), int(published * 1e9), n)
        self.counts[key] = n + 1

    def close(self) -> None:
        self.writer.finish()
        self.fh.close()


def add_log_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mcap", required=True, type=Path, metavar="FILE", help="the MCAP file to write")
    parser.add_argument("--robot", default=DEFAULT_ROBOT, help="the robot name (default %(default)s)")
    parser.add_argument("--duration", type=float, default=0.0,
                        help="stop after this many seconds (default: until Ctrl-C or SIGTERM)")
    add_zenoh_arguments(parser)


def main_log(args: argparse.Namespace) -> int:
    """``sctd log``: record the contract's keys into an MCAP file until stopped."""
    try:
        import mcap  # noqa: F401
    except ModuleNotFoundError:
        return fail("log", "needs mcap, which is not installed: pip install 'sctd[logs]'")
    prefix = Keys(args.robot).prefix
    samples: queue.SimpleQueue[tuple[str, bytes, float] | None] = queue.SimpleQueue()
    stop = threading.Event()
    log = McapLog(args.mcap)

    def writer() -> None:
        while (item := samples.get()) is not None:
            key, data, received = item
            kind = kind_of(key, prefix)
            if kind in RECORDED:
                log.add(key, kind, data, received)

    def on_sample(sample: zenoh.Sample) -> None:
        samples.put((str(sample.key_expr), sample.payload.to_bytes(), time.time()))

    t = threading.Thread(target=writer, name="sctd-log-writer")
    t.start()
    try:
        with session_from_args(args) as s, s.declare_subscriber(f"{prefix}/**", on_sample):
            print(f"sctd log: {prefix}/** -> {args.mcap}", file=sys.stderr, flush=True)
            wait_until(stop, args.duration)
    finally:
        samples.put(None)
        t.join()
        log.close()
    total = sum(log.counts.values())
    print(f"sctd log: {total} messages on {len(log.channels)} keys written to {args.mcap}"
          + (f" ({log.undecodable} not msgpack maps, left out)" if log.undecodable else ""),
          file=sys.stderr)
    return EXIT_OK


def read_log(path: Path) -> list[tuple[str, int, dict[str, Any]]]:
    """Every message of an ``sctd log`` file as (key, log time in ns, value), in log
    time order."""
    from mcap.reader import make_reader

    out = []
    with path.open("rb") as fh:
        for _schema, channel, message in make_reader(fh).iter_messages(log_time_order=True):
            if channel.message_encoding != "json":
                continue
            out.append((channel.topic, message.log_time, json.loads(message.data)))
    return out


def add_replay_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, metavar="FILE", help="an sctd log --mcap file")
    parser.add_argument("--speed", type=float, default=1.0,
                        help="time scale (default %(default)s: as logged)")
    parser.add_argument("--all", action="store_true",
                        help="also target, input and can (never while a daemon or robot answers)")
    parser.add_argument("--robot", default=None,
                        help="replay under this robot's prefix instead of the logged one")
    add_zenoh_arguments(parser)


def _live(s: zenoh.Session, keys: list[str], wait: float = 1.0) -> str | None:
    """A key of ``keys`` someone else publishes on now, or a daemon's skill queryable on
    the prefix, within ``wait`` s; None when nobody answers."""
    heard: list[str] = []
    subs = [s.declare_subscriber(k, lambda sample: heard.append(str(sample.key_expr)),
                                 allowed_origin=zenoh.Locality.REMOTE) for k in keys]
    try:
        end = time.monotonic() + wait
        while time.monotonic() < end and not heard:
            time.sleep(0.02)
    finally:
        for sub in subs:
            sub.undeclare()
    return heard[0] if heard else None


def main_replay(args: argparse.Namespace) -> int:
    """``sctd replay``: publish a log's observation keys again, at ``--speed``."""
    try:
        import mcap  # noqa: F401
    except ModuleNotFoundError:
        return fail("replay", "needs mcap, which is not installed: pip install 'sctd[logs]'")
    if not args.speed > 0:
        return fail("replay", f"--speed: expected a number > 0, got {args.speed}")
    try:
        messages = read_log(args.file)
    except Exception as e:  # the mcap reader raises many types on a bad file
        return fail("replay", f"{args.file}: not an sctd MCAP log ({type(e).__name__}: {e})")
    kinds = OBSERVATIONS + (COMMANDS if args.all else ())
    plan = []
    for key, t, value in messages:
        parts = key.split("/")
        if len(parts) < 3 or parts[0] != "sctd" or parts[2] not in kinds:
            continue
        if args.robot is not None:
            parts[1] = args.robot
        plan.append(("/".join(parts), t, value))
    if not plan:
        return fail("replay", f"{args.file}: nothing to replay ({', '.join(kinds)})")
    prefixes = sorted({"/".join(k.split("/")[:2]) for k, _, _ in plan})
    watched = [f"{p}/{k}" for p in prefixes for k in ("target", "state")] + [
        f"{p}/{k}/**" if k in ("objects", "input") else f"{p}/{k}"
        for p in prefixes for k in sorted({key.split("/")[2] for key, _, _ in plan})]
    stop = threading.Event()
    foreign: list[str] = []
    with session_from_args(args) as s:
        live = _live(s, sorted(set(watched)))
        if live is None:
            for p in prefixes:
                if any(r.ok is not None for r in s.get(f"{p}/skill", timeout=0.5)):
                    live = f"{p}/skill"
        if live is not None:
            print(f"sctd replay: a live program answers on {live}: not replaying over it",
                  file=sys.stderr)
            return EXIT_FAILED
        def on_foreign(sample: zenoh.Sample) -> None:
            foreign.append(str(sample.key_expr))
            stop.set()

        subs = [s.declare_subscriber(k, on_foreign, allowed_origin=zenoh.Locality.REMOTE)
                for k in sorted(set(watched))]
        pubs: dict[str, zenoh.Publisher] = {}
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        t0, start = plan[0][1], time.monotonic()
        sent = 0
        try:
            for key, t, value in plan:
                due = start + (t - t0) / 1e9 / args.speed
                if stop.wait(max(0.0, due - time.monotonic())):
                    break
                if key not in pubs:
                    pubs[key] = s.declare_publisher(key, encoding=MSGPACK)
                pubs[key].put(codec.pack(dict(value)))
                sent += 1
        except KeyboardInterrupt:
            pass
        finally:
            for sub in subs:
                sub.undeclare()
            for pub in pubs.values():
                pub.undeclare()
    if foreign:
        print(f"sctd replay: stopped after {sent} messages: a live program published on {foreign[0]}",
              file=sys.stderr)
        return EXIT_FAILED
    print(f"sctd replay: {sent} messages on {len(pubs)} keys from {args.file}", file=sys.stderr)
    return EXIT_OK
