"""``sctd log --mcap FILE`` and ``sctd replay FILE``: logs people can open.

``log`` records every key of the wire contract a robot's programs publish (targets,
status, input, state, objects, scene) into an MCAP file (the ``mcap`` package): one
channel per key, each message transcoded from msgpack to JSON, with a JSON Schema per
kind of key, so Foxglove (and any MCAP reader) decodes it. ``log_time`` is when the
sample arrived, ``publish_time`` the sender's ``stamp`` when it has one.

``replay`` publishes a log's observation keys (state, objects, scene, status) again,
msgpack as the contract has them, with their original spacing divided by ``--speed``,
after checking the file as it streams it (:func:`log_messages`: CRCs, bounded chunks,
keys of the contract only, JSON maps);
``target``, ``input`` and ``can`` only with ``--all``, and never while a live daemon or
robot answers on the same prefix: it refuses to start when one does, and stops when one
appears (a sample on a replayed key it did not send).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import queue
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import IO, Any

import zenoh

from ..app.errors import EXIT_FAILED, EXIT_OK, fail
from ..app.options import add_robot_argument
from ..files import FileError, open_regular
from ..timing import wait_until
from ..wire import Keys, codec
from ..wire.session import MSGPACK, add_zenoh_arguments, session_from_args
from .echo import decode

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
        try:
            self.writer = Writer(self.fh, enable_data_crcs=True)  # replay checks every byte it reads
            self.writer.start(profile="", library="sctd log")
        except BaseException:
            self.fh.close()
            raise
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
        try:
            self.writer.finish()
        finally:
            self.fh.close()

    def __enter__(self) -> McapLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _LogWriter(threading.Thread):
    """Writes the samples Zenoh's threads queue (:meth:`on_sample`) into ``log`` on a
    thread of its own, the keys under ``prefix`` of a recorded kind. A context manager:
    started on entry; on exit, what is queued is written and the thread joined."""

    def __init__(self, log: McapLog, prefix: str):
        super().__init__(name="sctd-log-writer")
        self.log, self.prefix = log, prefix
        self.samples: queue.SimpleQueue[tuple[str, bytes, float] | None] = queue.SimpleQueue()

    def on_sample(self, sample: zenoh.Sample) -> None:
        self.samples.put((str(sample.key_expr), sample.payload.to_bytes(), time.time()))

    def run(self) -> None:
        while (item := self.samples.get()) is not None:
            key, data, received = item
            kind = kind_of(key, self.prefix)
            if kind in RECORDED:
                self.log.add(key, kind, data, received)

    def __enter__(self) -> _LogWriter:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.samples.put(None)
        self.join()


def add_log_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mcap", required=True, type=Path, metavar="FILE", help="the MCAP file to write")
    add_robot_argument(parser)
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
    # Closed in reverse: the subscription and the session, then the writer (what was
    # queued is written), then the file.
    with McapLog(args.mcap) as log, _LogWriter(log, prefix) as writer, \
            session_from_args(args) as s, s.declare_subscriber(f"{prefix}/**", writer.on_sample):
        print(f"sctd log: {prefix}/** -> {args.mcap}", file=sys.stderr, flush=True)
        wait_until(threading.Event(), args.duration)
    total = sum(log.counts.values())
    print(f"sctd log: {total} messages on {len(log.channels)} keys written to {args.mcap}"
          + (f" ({log.undecodable} not msgpack maps, left out)" if log.undecodable else ""),
          file=sys.stderr)
    return EXIT_OK


MAX_LOG_BYTES = 64 * 1024**3  # an sctd log file; it is read as a stream, chunk by chunk
MAX_CHUNK = 64 * 1024 * 1024  # one MCAP chunk, unpacked (sctd log writes ~1 MB chunks)
MAX_MESSAGE = 1024 * 1024  # one message's JSON (a contract message is under 64 KiB)


class LogError(ValueError):
    """A log file replay will not read: ``file: where: problem``."""


def _contract_key(topic: str) -> str:
    """What is wrong with ``topic`` as a key of the wire contract ("" when nothing is):
    ``sctd/<robot>/<kind>`` or ``sctd/<robot>/<kind>/<name>`` with a robot and a name
    that are names (no wildcards, no empty chunks)."""
    parts = topic.split("/")
    if len(parts) not in (3, 4) or parts[0] != "sctd":
        return "not sctd/<robot>/<kind>[/<name>]"
    for chunk in parts[1:2] + parts[3:]:
        problem = codec.name_problem(chunk)
        if problem:
            return problem
    kind = parts[2]
    if kind not in (*RECORDED, "can") or (len(parts) == 4) != (kind in ("objects", "input")):
        return f"{kind!r} is not a key the log records here"
    return ""


def _unpack(chunk: Any, file: str, where: str) -> Any:
    """A chunk with its records unpacked, bounded before and while unpacking (a few kB of
    zstd can claim, or inflate to, gigabytes) and its CRC checked."""
    import io

    import zstandard

    if chunk.uncompressed_size > MAX_CHUNK:
        raise LogError(f"{file}: {where}: a chunk of {chunk.uncompressed_size} bytes unpacked, "
                       f"more than the {MAX_CHUNK} allowed")
    if chunk.compression == "zstd":
        reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data))
        data = reader.read(chunk.uncompressed_size + 1)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise LogError(f"{file}: {where}: compression {chunk.compression!r} (sctd log writes zstd)")
    if len(data) != chunk.uncompressed_size:
        raise LogError(f"{file}: {where}: a chunk that unpacks to other than its "
                       f"{chunk.uncompressed_size} bytes")
    return dataclasses.replace(chunk, compression="", data=data)


def log_messages(path: Path) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """Every message of an ``sctd log`` file as (key, log time in ns, value), in file
    order (the order they were logged), checked as it is read:

    - a regular file, read as a stream; every record at most :data:`MAX_CHUNK` bytes and
      every chunk unpacked no further than its declared size (at most the same);
    - every chunk's and the data section's CRC (a flipped bit is an error, not a value;
      ``sctd log`` writes both), and a data section that ends (the summary after it is
      not read: the messages are all before it);
    - every topic a key of the contract (no wildcards, no empty chunks) and every value
      a JSON map of at most :data:`MAX_MESSAGE` bytes.

    Raises
    ------
    LogError
        ``file: where: problem`` (``where``: the record or message's number).
    """
    file = str(path)
    try:
        fh = open_regular(path, MAX_LOG_BYTES, file)
    except FileError as e:
        raise LogError(str(e)) from None
    with fh:
        yield from read_messages(fh, file)


def read_messages(fh: IO[bytes], file: str) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """:func:`log_messages` on an open stream (``file`` names it in errors)."""
    from mcap.records import Channel, Chunk, DataEnd, Message
    from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

    channels: dict[int, str] = {}
    n = 0
    where = "the header"
    ended = False
    try:
        for k, record in enumerate(StreamReader(fh, validate_crcs=True, emit_chunks=True,
                                                record_size_limit=MAX_CHUNK).records):
            where = f"record {k}"
            records = breakup_chunk(_unpack(record, file, where), validate_crc=True) \
                if isinstance(record, Chunk) else [record]
            if isinstance(record, DataEnd):  # its CRC checked: every message is read
                ended = True
                break
            for r in records:
                if isinstance(r, Channel):
                    problem = _contract_key(r.topic)
                    if problem:
                        raise LogError(f"{file}: {where}: topic {r.topic!r}: {problem}")
                    channels[r.id] = r.topic if r.message_encoding == "json" else ""
                elif isinstance(r, Message):
                    n += 1
                    topic = channels.get(r.channel_id)
                    if topic is None:
                        raise LogError(f"{file}: message {n}: channel {r.channel_id} was never declared")
                    if topic:
                        yield topic, r.log_time, _value(r.data, file, n)
    except CRCValidationError as e:
        raise LogError(f"{file}: {where}: CRC {e.actual:#010x}, the record says "
                       f"{e.expected:#010x}: the file is damaged") from None
    except LogError:
        raise
    except Exception as e:  # the mcap reader and zstd raise many kinds on a bad file
        raise LogError(f"{file}: {where}: not an MCAP file sctd can read ({type(e).__name__}: "
                       f"{str(e)[:120]})") from None
    if not ended:
        raise LogError(f"{file}: {where}: the data section has no end (the file is cut short or damaged)")


def _value(data: bytes, file: str, n: int) -> dict[str, Any]:
    if len(data) > MAX_MESSAGE:
        raise LogError(f"{file}: message {n}: {len(data)} bytes, more than the {MAX_MESSAGE} allowed")
    try:
        value = json.loads(data)
    except (ValueError, RecursionError):
        raise LogError(f"{file}: message {n}: not JSON") from None
    if not isinstance(value, dict):
        raise LogError(f"{file}: message {n}: expected a JSON map, got {type(value).__name__}")
    return value


def read_log(path: Path) -> list[tuple[str, int, dict[str, Any]]]:
    """Every message of an ``sctd log`` file (:func:`log_messages`), as a list."""
    return list(log_messages(path))


def add_replay_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, metavar="FILE", help="an sctd log --mcap file")
    parser.add_argument("--speed", type=float, default=1.0,
                        help="time scale (default %(default)s: as logged)")
    parser.add_argument("--all", action="store_true",
                        help="also target, input and can (never while a daemon or robot answers)")
    add_robot_argument(parser, None, "replay under this robot's prefix instead of the logged one")
    add_zenoh_arguments(parser)


def _live(s: zenoh.Session, keys: list[str], wait: float = 1.0) -> str | None:
    """A key of ``keys`` someone else publishes on now, or a daemon's skill queryable on
    the prefix, within ``wait`` s; None when nobody answers."""
    heard: list[str] = []
    with ExitStack() as stack:
        for k in keys:
            stack.enter_context(s.declare_subscriber(k, lambda sample: heard.append(str(sample.key_expr)),
                                                     allowed_origin=zenoh.Locality.REMOTE))
        end = time.monotonic() + wait
        while time.monotonic() < end and not heard:
            time.sleep(0.02)
    return heard[0] if heard else None


def _replayed(file: Path, kinds: tuple[str, ...], robot: str | None
              ) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """The messages of ``kinds`` to replay from ``file``, under ``robot``'s prefix when
    given (a stream: the file is read twice, once to know what it holds, once to replay
    it)."""
    for key, t, value in log_messages(file):
        parts = key.split("/")
        if parts[2] not in kinds:
            continue
        if robot is not None:
            parts[1] = robot
        yield "/".join(parts), t, value


def _watched(held: set[tuple[str, str]]) -> tuple[list[str], list[str]]:
    """The prefixes a replay of ``held`` (robot, kind) publishes under, and the keys on
    which a live program would show: each prefix's target and state, and what it
    replays."""
    prefixes = sorted({f"sctd/{robot}" for robot, _ in held})
    watched = [f"{p}/{k}" for p in prefixes for k in ("target", "state")] + [
        f"{p}/{k}/**" if k in ("objects", "input") else f"{p}/{k}"
        for p in prefixes for k in sorted({kind for _, kind in held})]
    return prefixes, sorted(set(watched))


def _live_program(s: zenoh.Session, watched: list[str], prefixes: list[str]) -> str | None:
    """Where a live program answers: one of the ``watched`` keys it publishes on, or the
    skill queryable of one of the ``prefixes``; None when nobody does."""
    live = _live(s, watched)
    if live is None:
        for p in prefixes:
            if any(r.ok is not None for r in s.get(f"{p}/skill", timeout=0.5)):
                live = f"{p}/skill"
    return live


def _publish(s: zenoh.Session, messages: Iterator[tuple[str, int, dict[str, Any]]], speed: float,
             stop: threading.Event) -> tuple[int, int]:
    """Publish ``messages`` (key, log time in ns, value) with their logged spacing divided
    by ``speed``, until they end, ``stop`` is set or Ctrl-C; returns how many were sent
    on how many keys."""
    with ExitStack() as stack:
        pubs: dict[str, zenoh.Publisher] = {}
        t0, start = None, time.monotonic()
        sent = 0
        try:
            for key, t, value in messages:
                t0 = t if t0 is None else t0
                due = start + (t - t0) / 1e9 / speed
                if stop.wait(max(0.0, due - time.monotonic())):
                    break
                if key not in pubs:
                    pubs[key] = stack.enter_context(s.declare_publisher(key, encoding=MSGPACK))
                pubs[key].put(codec.pack(dict(value)))
                sent += 1
        except KeyboardInterrupt:
            pass
    return sent, len(pubs)


def main_replay(args: argparse.Namespace) -> int:
    """``sctd replay``: publish a log's observation keys again, at ``--speed``."""
    try:
        import mcap  # noqa: F401
    except ModuleNotFoundError:
        return fail("replay", "needs mcap, which is not installed: pip install 'sctd[logs]'")
    if not args.speed > 0:
        return fail("replay", f"--speed: expected a number > 0, got {args.speed}")
    if args.robot is not None and codec.name_problem(args.robot):
        return fail("replay", f"--robot: {codec.name_problem(args.robot)}")
    kinds = OBSERVATIONS + (COMMANDS if args.all else ())
    try:
        held = {(k.split("/")[1], k.split("/")[2]) for k, _, _ in _replayed(args.file, kinds, args.robot)}
    except LogError as e:
        return fail("replay", str(e))
    if not held:
        return fail("replay", f"{args.file}: nothing to replay ({', '.join(kinds)})")
    prefixes, watched = _watched(held)
    stop = threading.Event()
    foreign: list[str] = []

    def on_foreign(sample: zenoh.Sample) -> None:
        foreign.append(str(sample.key_expr))
        stop.set()

    with session_from_args(args) as s:
        live = _live_program(s, watched, prefixes)
        if live is not None:
            print(f"sctd replay: a live program answers on {live}: not replaying over it",
                  file=sys.stderr)
            return EXIT_FAILED
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        try:
            with ExitStack() as stack:
                for k in watched:
                    stack.enter_context(s.declare_subscriber(k, on_foreign,
                                                             allowed_origin=zenoh.Locality.REMOTE))
                sent, keys = _publish(s, _replayed(args.file, kinds, args.robot), args.speed, stop)
        except LogError as e:  # changed on disk between the two readings
            return fail("replay", str(e))
    if foreign:
        print(f"sctd replay: stopped after {sent} messages: a live program published on {foreign[0]}",
              file=sys.stderr)
        return EXIT_FAILED
    print(f"sctd replay: {sent} messages on {keys} keys from {args.file}", file=sys.stderr)
    return EXIT_OK
