"""``sctd input BACKEND``: an input device bridged to the wire contract (``docs/input.md``).

- :mod:`.device`: what a backend and an open device provide;
- :mod:`.registry`: the built-in backends and the ``sctd.input`` entry points;
- :mod:`.mapping`: the mapping file (axes, dead bands, button roles);
- :mod:`.bridge`: the fixed-rate loop that publishes ``sctd/<robot>/input/<name>``;
- backends: :mod:`.gamepad` (SDL2), :mod:`.spacemouse` (hidapi), :mod:`.emg`
  (BrainFlow), :mod:`.keyboard` (the terminal).

``python -m sctd_services.input`` takes the same flags as ``sctd input``.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from sctd.app.errors import EXIT_FAILED, EXIT_USAGE, fail
from sctd.app.options import add_robot_argument
from sctd.wire.session import MSGPACK, add_zenoh_arguments, session_from_args

from .device import Backend, InputError
from .registry import backend_names, get_backend


def _backends() -> list[Backend]:
    out = []
    for name in backend_names():
        try:
            out.append(get_backend(name))
        except InputError as e:  # a broken plug-in must not hide the others
            fail("input", str(e))  # said, and the other backends listed
    return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The bridge's flags (``sctd input``) and every backend's own."""
    backends = _backends()
    p.add_argument("backend", nargs="?", metavar="BACKEND",
                   help=f"the kind of device: {', '.join(b.name for b in backends)}")
    p.add_argument("--list", action="store_true",
                   help="name every backend, whether its library is installed, and the devices "
                        "each sees now (no network discovery), then exit")
    p.add_argument("--device", metavar="SELECTOR",
                   help="which device: its index in --list or a part of its name (default: the first)")
    p.add_argument("--name", help="publish on sctd/<robot>/input/NAME (default: the backend's name)")
    p.add_argument("--map", metavar="FILE.yaml",
                   help="the mapping file: axes, scales, inversion, dead bands, button roles "
                        "(default: the backend's shipped one; docs/input.md)")
    p.add_argument("--axes", type=int, choices=(3, 6), default=3, help="length of u (default 3)")
    p.add_argument("--rate", type=float, default=100.0,
                   help="messages per second, 20 to 1000 (default %(default)s)")
    add_robot_argument(p)
    p.add_argument("--print", action="store_true", dest="echo",
                   help="also print the published u and buttons, 10 times a second")
    for b in backends:
        b.add_arguments(p.add_argument_group(f"{b.name}: {b.help}"))
    add_zenoh_arguments(p)


def list_backends(out=sys.stdout) -> int:
    """``--list``: every backend, its library's state and the devices it sees."""
    for b in _backends():
        missing = b.missing()
        print(f"{b.name:<11} {b.help}", file=out)
        if missing:
            print(f"{'':<11} not available: {missing}", file=out)
            continue
        try:
            devices = b.devices()
        except InputError as e:
            print(f"{'':<11} {e}", file=out)
            continue
        if not devices:
            print(f"{'':<11} no device found", file=out)
        for d in devices:
            print(f"{'':<11} {d.index}: {d.name}" + (f" ({d.detail})" if d.detail else ""), file=out)
    return 0


def run(args: argparse.Namespace) -> int:
    """Bridge the chosen device until SIGINT/SIGTERM; 2 for bad flags or files, 1 when the
    device cannot be opened."""
    from .bridge import MAX_RATE, MIN_RATE, Bridge
    from .bridge import run as run_bridge

    if args.list:
        return list_backends()
    if not args.backend:
        return _usage("give a BACKEND or --list")
    if not MIN_RATE <= args.rate <= MAX_RATE:
        return _usage(f"--rate: between {MIN_RATE:g} and {MAX_RATE:g} Hz, got {args.rate:g}")
    try:
        backend = get_backend(args.backend)
    except InputError as e:
        return _usage(str(e))
    missing = backend.missing()
    if missing:
        return _usage(f"{backend.name}: {missing}")
    try:
        mapping = _mapping(args.map, backend)
    except InputError as e:
        return _usage(str(e))
    stop = threading.Event()

    def on_signal(*_: object) -> None:
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    try:
        special = backend.run_special(args)
    except InputError as e:
        return _fail(str(e))
    if special is not None:
        return special
    name = args.name or backend.name
    try:
        device = backend.open(args.device, args)
    except InputError as e:
        return _fail(str(e))
    with device, session_from_args(args) as session:
        from sctd.wire import Keys

        key = Keys(args.robot).input(name)
        pub = session.declare_publisher(key, encoding=MSGPACK)
        bridge = Bridge(device, mapping, args.axes, pub.put)
        print(f"sctd input: {backend.name} {device.name!r} -> {key} at {args.rate:g} Hz, "
              f"mapping {mapping.origin}", file=sys.stderr, flush=True)
        try:
            run_bridge(bridge, args.rate, stop, _echo(args.rate) if args.echo else None)
        finally:
            pub.undeclare()
        s = bridge.stats
        print(f"sctd input: stopped after {s.published} messages ({s.disconnected} zero while "
              f"disconnected, {s.errors} read errors); published zero", file=sys.stderr)
    return 0


def _mapping(path: str | None, backend: Backend):
    """The mapping file ``path`` (default: the backend's shipped one, or the identity),
    checked against the backend's numbering; InputError naming the file and field."""
    from .mapping import check_range, identity, load_mapping, shipped_mapping

    mapping = (load_mapping(path) if path else
               shipped_mapping(backend.default_map) if backend.default_map else identity())
    if mapping.origin != "identity":  # (which names every axis a backend could have)
        check_range(mapping, backend.name, backend.device_axes, backend.device_buttons)
    return mapping


def _echo(rate: float):
    every = max(1, round(rate / 10.0))

    def show(bridge) -> None:
        if bridge.seq % every == 0:
            u, b = bridge.last
            print("u " + " ".join(f"{x:+.2f}" for x in u) + f"  mode {b[0]} enable {b[1]} escape {b[2]}",
                  flush=True)
    return show


def _usage(msg: str) -> int:
    return fail("input", msg, EXIT_USAGE)


def _fail(msg: str) -> int:
    return fail("input", msg, EXIT_FAILED)
