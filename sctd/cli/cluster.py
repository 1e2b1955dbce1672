"""``sctd cluster scheduler`` / ``sctd cluster worker``: a Dask cluster for lockstep trials.

Dask's own ``dask scheduler`` and ``dask worker`` with safe defaults (docs/cluster.md):
they bind 127.0.0.1 unless ``--host`` says otherwise, serve no dashboard, and listen on
another address only with mutual TLS (``--certs`` from ``sctd certs``)::

    sctd cluster scheduler                                # tcp://127.0.0.1:8786
    sctd cluster worker tcp://127.0.0.1:8786 --nworkers 2
    sctd eval --skill pour --lockstep --scheduler tcp://127.0.0.1:8786

Each prints its address(es) on one line once listening and runs until SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
from collections.abc import Callable, Coroutine
from typing import Any

from sctd_services.eval.cluster import (
    SCHEDULER_PORT,
    SERVER_ROLE,
    ClusterError,
    TlsFiles,
    serve_scheduler,
    serve_workers,
    tls_files,
)

from ..app.errors import EXIT_OK, fail


def _add_listen_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--host", default="127.0.0.1",
                   help="the address to listen on (default %(default)s; another needs --certs)")
    p.add_argument("--certs", metavar="DIR",
                   help=f"a sctd certs --out folder: mutual TLS with its CA and the {SERVER_ROLE} key pair")
    p.add_argument("--tls-ca", metavar="PEM", help="the CA that signed every end's certificate")
    p.add_argument("--tls-cert", metavar="PEM", help="this end's certificate (server and client use)")
    p.add_argument("--tls-key", metavar="PEM", help="this end's key")


def add_scheduler_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", type=int, default=SCHEDULER_PORT,
                   help="the port to listen on (default %(default)s; 0: any free one)")
    _add_listen_arguments(p)


def add_worker_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scheduler", metavar="ADDR", help="the scheduler's address (tcp://127.0.0.1:8786)")
    p.add_argument("--nworkers", type=int, default=1,
                   help="worker processes, one trial at a time each (default %(default)s)")
    _add_listen_arguments(p)


def _tls(args: argparse.Namespace) -> TlsFiles | None:
    return tls_files(args.tls_ca, args.tls_cert, args.tls_key, args.certs, SERVER_ROLE)


def _run(serve: Callable[[asyncio.Event], Coroutine[Any, Any, None]]) -> None:
    """Run ``serve(stop)`` until SIGINT or SIGTERM sets ``stop``."""

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await serve(stop)

    asyncio.run(main())


def main_scheduler(args: argparse.Namespace) -> int:
    try:
        tls = _tls(args)
        _run(lambda stop: serve_scheduler(
            args.host, args.port, tls,
            lambda address: print(f"sctd cluster scheduler: {address}", flush=True), stop))
    except (ClusterError, OSError) as e:
        return fail("cluster scheduler", str(e))
    return EXIT_OK


def main_worker(args: argparse.Namespace) -> int:
    if args.nworkers < 1:
        return fail("cluster worker", "--nworkers: must be >= 1")
    try:
        tls = _tls(args)
        _run(lambda stop: serve_workers(
            args.scheduler, args.nworkers, args.host, tls,
            lambda workers: print(f"sctd cluster worker: {' '.join(workers)}", flush=True), stop))
    except (ClusterError, OSError) as e:
        return fail("cluster worker", str(e))
    return EXIT_OK
