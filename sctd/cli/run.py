"""``sctd run``, ``sctd inspect`` and ``sctd swap``."""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import threading
from typing import TYPE_CHECKING

from ..runtime.zsession import add_zenoh_arguments

if TYPE_CHECKING:
    from ..runtime.controller import RuntimeConfig


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    from dataclasses import fields

    from ..runtime.controller import RuntimeConfig

    p.add_argument("--skill", required=True, help="skill YAML file")
    # One flag per RuntimeConfig setting, named and documented there.
    for f in fields(RuntimeConfig):
        if "help" not in f.metadata:
            continue
        kind = type(f.default)
        p.add_argument(f"--{f.name.replace('_', '-')}", type=kind, default=f.default,
                       help=f"{f.metadata['help']} (default %(default)s)")
    p.add_argument("--no-stamp-check", action="store_true",
                   help="judge input, state and object ages by arrival time only (senders with "
                        "unsynchronised clocks)")
    p.add_argument("--spin-us", type=float, default=100.0,
                   help="us before each deadline spent spinning instead of sleeping (default %(default)s)")
    p.add_argument("--rt-priority", type=int, default=10,
                   help="SCHED_FIFO priority of the tick thread, 0 for none; falls back to normal "
                        "priority when not permitted (default %(default)s)")
    p.add_argument("--cpu", type=int, default=None,
                   help="pin the tick thread to this CPU (best with that CPU kept free of other work, "
                        "e.g. isolcpus)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--stats-json", action="store_true", help="print final statistics as JSON on exit")
    add_zenoh_arguments(p)


def runtime_config(args: argparse.Namespace) -> RuntimeConfig:
    """The RuntimeConfig of parsed ``sctd run`` flags.

    Raises
    ------
    ValueError
        A setting out of range, naming its flag.
    """
    from dataclasses import fields

    from ..runtime import codec
    from ..runtime.controller import RuntimeConfig

    kw = {f.name: getattr(args, f.name) for f in fields(RuntimeConfig) if "help" in f.metadata}
    for name, value in kw.items():
        if isinstance(value, float) and not (value >= 0 if name == "deadband" else value > 0):
            raise ValueError(f"--{name.replace('_', '-')} must be {'>= 0' if name == 'deadband' else '> 0'}")
    codec.Keys(kw["robot"])  # one key chunk
    return RuntimeConfig(stamp_check=not args.no_stamp_check, **kw)


def main_run(args: argparse.Namespace) -> int:
    import zenoh

    from ..runtime.daemon import Daemon, ingress_limits
    from ..runtime.zsession import close_session, open_session
    from ..skill import SkillError, load_skill

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stderr)
    try:
        skill = load_skill(args.skill)
    except SkillError as e:
        print(f"sctd run: {e}", file=sys.stderr)
        return 2
    try:
        config = runtime_config(args)
    except ValueError as e:
        print(f"sctd run: {e}", file=sys.stderr)
        return 2
    # Signals are caught before anything is bound, so that a SIGINT/SIGTERM that comes
    # while the daemon is still starting also ends it cleanly (exit 0, port freed).
    stop = threading.Event()

    def on_signal(signum, frame):
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    try:
        session = open_session(args.listen, args.connect, args.zenoh_config,
                               **ingress_limits(config.robot))
    except (ValueError, zenoh.ZError) as e:
        print(f"sctd run: cannot open Zenoh session: {e}", file=sys.stderr)
        return 2
    try:
        if args.cpu is not None and not 0 <= args.cpu < (os.cpu_count() or 1):
            print(f"sctd run: --cpu {args.cpu}: this machine has CPUs 0-{(os.cpu_count() or 1) - 1}",
                  file=sys.stderr)
            return 2
        daemon = Daemon(skill, session, config, spin=args.spin_us * 1e-6, rt_priority=args.rt_priority,
                        cpu=args.cpu, stop_event=stop)
        stats = daemon.run(args.duration)
    finally:
        close_session(session)
    if args.stats_json:
        print(json.dumps(stats))
    return 0


def add_inspect_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("skill", help="skill YAML file")
    p.add_argument("--json", action="store_true", help="machine-readable output")


def main_inspect(args: argparse.Namespace) -> int:
    from ..skill import SkillError, load_skill, skill_summary

    try:
        s = skill_summary(load_skill(args.skill))
    except SkillError as e:
        print(f"sctd inspect: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    print(f"skill {s['name']} (id {s['id']}), object {s['object']}: {s['description']}")
    print(f"  limits: {s['limits']['max_linear_speed']} m/s, {s['limits']['max_angular_speed']} rad/s")
    for name, f in s["frames"].items():
        print(f"  frame {name}: parent {f['parent']}, pose {f['pose']}")
    for st in s["states"]:
        mark = " (start)" if st["name"] == s["start"] else ""
        mark += " (end)" if st["name"] == s["end"] else ""
        print(f"  state {st['name']}{mark}")
        for m in st["input_mappings"]:
            if m["type"] == "linear":
                print(f"    IM linear on {m['frame']}: {_describe_matrix(m['matrix'])}")
            else:
                print(f"    IM vector_field on {m['frame']}: {m['fields']} fields, mode {m['mode']}")
        for c in st["active_constraints"]:
            extra = {k: v for k, v in c.items() if k not in ("type", "frame")}
            print(f"    AC {c['type']} on {c['frame']}: {extra}")
    for t in s["transitions"]:
        extra = {k: v for k, v in t.items() if k not in ("from", "to", "type")}
        print(f"  {t['from']} -> {t['to']} ({t['type']}): {extra}")
    for f in s["fields"]:
        print(f"  field {f}")
    for c in s["candidate_frames"]:
        print(f"  candidate frame {c}")
    return 0


def _describe_matrix(m: list[list[float]]) -> str:
    names = ("tx", "ty", "tz", "rx", "ry", "rz")
    cols = []
    for j in range(len(m[0])):
        terms = [f"{m[i][j]:+g}{names[i]}" for i in range(6) if m[i][j] != 0]
        cols.append(f"u{j}->" + ("".join(terms) if terms else "none"))
    return ", ".join(cols)


def add_swap_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("skill", help="skill YAML file to send to the running daemon")
    p.add_argument("--robot", default="edan")
    p.add_argument("--timeout", type=float, default=10.0, help="s to wait for the daemon's reply")
    add_zenoh_arguments(p)


def main_swap(args: argparse.Namespace) -> int:
    import msgpack

    from ..runtime.codec import Keys
    from ..runtime.zsession import session_from_args
    from ..skill import Bundle, SkillError, bundle_from_file, skill_from_bundle

    try:
        bundle = bundle_from_file(args.skill)
        skill_from_bundle(bundle)  # refuse locally what the daemon would refuse
        payload = bundle.pack()
        Bundle.unpack(payload)  # the size limit too
    except SkillError as e:
        print(f"sctd swap: {e}", file=sys.stderr)
        return 2
    with session_from_args(args) as session:
        replies = session.get(Keys(args.robot).skill, payload=payload, timeout=args.timeout)
        for reply in replies:
            if reply.ok is not None:
                body = msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False)
                print(body.get("id"))
                return 0
            body = _err_body(reply.err.payload.to_bytes()) if reply.err is not None else "no reply"
            print(f"sctd swap: refused by the daemon: {body}", file=sys.stderr)
            return 1
    print(f"sctd swap: no daemon answered on {Keys(args.robot).skill} within {args.timeout} s",
          file=sys.stderr)
    return 1


def _err_body(data: bytes) -> str:
    import msgpack

    try:
        body = msgpack.unpackb(data, raw=False)
        return body.get("error", str(body)) if isinstance(body, dict) else str(body)
    except Exception:
        return data.decode(errors="replace")
