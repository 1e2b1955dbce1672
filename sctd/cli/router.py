"""``sctd router``: a Zenoh router from the eclipse-zenoh package, until SIGINT/SIGTERM.

With ``--config FILE`` (``sctd certs`` writes ``zenoh/router.json5``: mutual TLS and the
access control of the roles) the file is the whole configuration, with ``mode`` forced
to ``router``. Without it: a router on ``tcp/127.0.0.1:7447``, no authentication and no
access control, the hub the loopback defaults connect to (for trying things on one
machine only). The same files are meant for ``zenohd -c FILE`` in production (untested
here: zenohd is not installable from our registries).

Stopping is bounded: on SIGINT/SIGTERM the session is closed from a helper thread
(:func:`sctd.wire.session.close_session`) and waited for at most :data:`CLOSE_WAIT`
s, and then the process ends at once (``os._exit``) with 0 when the session closed in
time and :data:`~sctd.app.errors.EXIT_FORCED` (3) when it did not. The interpreter's
own shutdown is skipped on purpose: it would wait for a session still closing
(``Session.close`` can block for about 10 s, e.g. while a listen endpoint is still being
retried), and on the loaded 2-core machine it took 1.5-10 s even after a clean close
(freeing what ``sctd.runtime`` imports), so a service manager or a test that stops the
router could not count on it ending.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
from typing import NoReturn

import zenoh

from sctd.timing import wait_until
from sctd.wire.session import HUB, close_session

from ..app.errors import EXIT_CODES, EXIT_FAILED, EXIT_FORCED, EXIT_OK, fail

CLOSE_WAIT = 2.0  # s the session may take to close after SIGINT/SIGTERM


def add_router_arguments(p) -> None:
    p.add_argument("--config", metavar="FILE",
                   help=f"Zenoh json5 config of the router (default: {HUB}, no authentication)")
    p.epilog = (f"{EXIT_CODES}; {EXIT_FORCED} stopped by SIGINT/SIGTERM, but Zenoh did not close "
                f"the session within {CLOSE_WAIT:g} s, so the process exited without it")


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
        return fail("router", f"{args.config or HUB}: cannot start: {e}", EXIT_FAILED)
    try:
        listen = json.loads(conf.get_json("listen/endpoints"))
        print(f"sctd router: zid {s.info.zid()} listening on {', '.join(map(str, listen))}",
              flush=True)
        wait_until(stop)  # (a signal may be taken by one of Zenoh's threads: see there)
    except BaseException:  # reported as it is, the session closed as on a signal
        close_session(s, timeout=CLOSE_WAIT)
        raise
    _exit_now(_close(s))


def _close(s: zenoh.Session) -> int:
    """Close ``s`` within CLOSE_WAIT s: EXIT_OK, or EXIT_FORCED (said on stderr)."""
    if close_session(s, timeout=CLOSE_WAIT):
        return EXIT_OK
    return fail("router", f"the Zenoh session did not close within {CLOSE_WAIT:g} s; exiting "
                f"without it (exit {EXIT_FORCED})", EXIT_FORCED)


def _exit_now(code: int) -> NoReturn:
    """End the process with ``code`` without the interpreter's shutdown (module doc)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or file: nothing left to flush
            pass
    os._exit(code)
