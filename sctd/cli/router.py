"""``sctd router``: a Zenoh router from the eclipse-zenoh package, until SIGINT/SIGTERM.

With ``--config FILE`` (``sctd certs`` writes ``zenoh/router.json5``: mutual TLS and the
access control of the roles) the file is the whole configuration, with ``mode`` forced
to ``router``. Without it: a router on ``tcp/127.0.0.1:7447``, no authentication and no
access control, the hub the loopback defaults connect to (for trying things on one
machine only). The same files are meant for ``zenohd -c FILE`` in production (untested
here: zenohd is not installable from our registries).
"""

from __future__ import annotations

import json
import signal
import threading

import zenoh

from sctd.runtime.zsession import HUB, close_session

from .errors import EXIT_OK, fail


def add_router_arguments(p) -> None:
    p.add_argument("--config", metavar="FILE",
                   help=f"Zenoh json5 config of the router (default: {HUB}, no authentication)")


def router_config(path: str | None) -> zenoh.Config:
    """The router's config: ``path`` with mode router, or the loopback hub."""
    if path is not None:
        conf = zenoh.Config.from_file(path)
    else:
        conf = zenoh.Config()
        conf.insert_json5("listen/endpoints", json.dumps([HUB]))
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("transport/link/protocols", '["tcp"]')
        conf.insert_json5("transport/shared_memory/enabled", "false")
    conf.insert_json5("mode", '"router"')
    return conf


def main_router(args) -> int:
    try:
        conf = router_config(args.config)
    except (zenoh.ZError, OSError) as e:
        return fail("router", f"{args.config}: {e}")
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        s = zenoh.open(conf)
    except zenoh.ZError as e:
        return fail("router", f"{args.config or HUB}: cannot start: {e}", 1)
    try:
        listen = json.loads(conf.get_json("listen/endpoints"))
        print(f"sctd router: zid {s.info.zid()} listening on {', '.join(map(str, listen))}",
              flush=True)
        stop.wait()
    finally:
        close_session(s, timeout=2.0)
    return EXIT_OK
