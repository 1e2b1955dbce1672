"""Lockstep trials on a Dask scheduler's workers (``docs/cluster.md``).

:func:`connect` turns a scheduler's address into a :class:`concurrent.futures.Executor`
that :func:`sctd_services.eval.evaluate.evaluate` submits trials to, as it does to a pool
of local processes. A worker on another host has none of this machine's files, so the
evaluation ships each trial's skill bundle and task file with it
(:attr:`ClusterExecutor.ships_trials`).

Safe defaults: a plain ``tcp://`` address must be on loopback; anything else needs
``tls://`` and the certificates of ``sctd certs`` (mutual TLS: the CA signs the
scheduler's, the workers' and the client's certificates; :class:`TlsFiles`). The
scheduler and workers of :func:`serve_scheduler` and :func:`serve_workers` bind
127.0.0.1 unless told otherwise and serve no dashboard: their HTTP servers bind
127.0.0.1 with no routes.

A worker that dies takes the trials it was running with it; the scheduler runs them
again elsewhere. The executor hears of it from the scheduler's ``remove-worker`` event
and reports each such death as a :class:`Rerun` (``worker tcp://... died: trials
seed 3, seed 4 re-run``).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import threading
import uuid
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, InvalidStateError
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sctd.wire.session import is_loopback

log = logging.getLogger("sctd.cluster")

CONNECT_TIMEOUT = 10.0  # s to reach the scheduler and see a worker
SCHEDULER_PORT = 8786
SERVER_ROLE = "sctd-router"  # of sctd certs: the one certificate for serverAuth and clientAuth
# Nothing served over HTTP: no dashboard, no metrics, no info pages (plain HTTP, no auth).
QUIET_HTTP: dict[str, list[str]] = {"distributed.scheduler.http.routes": [],
                                     "distributed.worker.http.routes": []}
LOCAL_HTTP = "127.0.0.1:0"


class ClusterError(RuntimeError):
    """A scheduler that cannot be used: the message names the address and what was tried."""


@dataclass(frozen=True)
class TlsFiles:
    """The PEM files of one end of a mutual-TLS connection: the CA that signs every
    end's certificate, this end's certificate and its key."""

    ca: Path
    cert: Path
    key: Path

    @classmethod
    def from_folder(cls, folder: str | Path, role: str) -> TlsFiles:
        """``ca.pem``, ``<role>.pem`` and ``<role>-key.pem`` of a ``sctd certs --out``
        folder. The scheduler and the workers listen, so they need a certificate for
        server authentication: ``sctd-router``'s (:data:`SERVER_ROLE`); a client only
        connects, and any role's certificate does."""
        d = Path(folder)
        return cls(d / "ca.pem", d / f"{role}.pem", d / f"{role}-key.pem")

    def check(self) -> None:
        for what, p in (("CA", self.ca), ("certificate", self.cert), ("key", self.key)):
            if not p.is_file():
                raise ClusterError(f"{p}: no such file (the TLS {what}; sctd certs --out DIR makes them)")

    def security(self) -> Any:
        """A ``distributed.Security`` that requires TLS on every connection."""
        from distributed.security import Security

        self.check()
        return Security(tls_ca_file=str(self.ca), tls_client_cert=str(self.cert),
                        tls_client_key=str(self.key), tls_scheduler_cert=str(self.cert),
                        tls_scheduler_key=str(self.key), tls_worker_cert=str(self.cert),
                        tls_worker_key=str(self.key), require_encryption=True)


def tls_files(ca: str | None, cert: str | None, key: str | None, certs: str | None,
              role: str) -> TlsFiles | None:
    """The TLS files the flags give: ``--tls-ca/--tls-cert/--tls-key`` together, or a
    ``sctd certs`` folder (``--certs``, ``role``'s pair), or none (None)."""
    given = [x for x in (ca, cert, key) if x]
    if given and certs:
        raise ClusterError("--certs and --tls-ca/--tls-cert/--tls-key: give one or the other")
    if given and len(given) != 3:
        raise ClusterError("--tls-ca, --tls-cert and --tls-key go together")
    if given:
        return TlsFiles(Path(str(ca)), Path(str(cert)), Path(str(key)))
    return TlsFiles.from_folder(certs, role) if certs else None


def _split(address: str) -> tuple[str, str]:
    """``(scheme, host)`` of ``scheme://host:port`` (no scheme: Dask's ``tcp``)."""
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    host = rest.rsplit(":", 1)[0] if ":" in rest else rest
    return scheme, host.strip("[]")



def check_address(address: str, tls: TlsFiles | None, what: str = "--scheduler") -> str:
    """``address`` with its scheme, or :class:`ClusterError`: plain ``tcp://`` only to a
    loopback address; ``tls://`` only with ``tls`` files (and those files with it)."""
    scheme, host = _split(address)
    if scheme not in ("tcp", "tls") or not host:
        raise ClusterError(f"{what} {address}: expected tcp://HOST:PORT or tls://HOST:PORT")
    if scheme == "tcp" and not is_loopback(host):
        raise ClusterError(f"{what} {address}: plain tcp:// is for loopback only (127.0.0.1); across "
                           "hosts use tls:// with the certificates of sctd certs (--certs DIR)")
    if scheme == "tls" and tls is None:
        raise ClusterError(f"{what} {address}: tls:// needs --certs DIR or --tls-ca/--tls-cert/--tls-key")
    if scheme == "tcp" and tls is not None:
        raise ClusterError(f"{what} {address}: TLS files given for a plain tcp:// address; use tls://")
    return address if "://" in address else f"tcp://{address}"


@dataclass(frozen=True)
class Rerun:
    """A worker that died with trials on it, which the scheduler runs again elsewhere."""

    worker: str
    trials: tuple[str, ...]

    def __str__(self) -> str:
        return f"worker {self.worker} died: trials {', '.join(self.trials)} re-run"


class TrialLost(ClusterError):
    """The scheduler gave up on a trial: the workers that ran it died too often."""


def _explained(exc: BaseException, address: str, name: str) -> BaseException:
    """A trial's error: a Dask ``KilledWorker`` as a :class:`TrialLost` that says so."""
    from distributed import KilledWorker

    if isinstance(exc, KilledWorker):
        return TrialLost(f"--scheduler {address}: trial {name}: gave up after the workers running it "
                         f"died ({exc})")
    return exc


class ClusterExecutor(Executor):
    """Trials on a Dask scheduler's workers, as a ``concurrent.futures`` executor.

    Made by :func:`connect`; closes its client on :meth:`shutdown` (a context manager,
    as every executor). ``fn`` given to :meth:`submit` may carry a ``name`` (a trial's
    :class:`~sctd_services.eval.evaluate.Trial`): reruns are reported by it.

    Attributes
    ----------
    ships_trials : bool
        True: the evaluation sends each trial's skill and task with it.
    reruns : list of Rerun
        Every worker death that sent trials of this executor to other workers.
    """

    ships_trials = True

    def __init__(self, client: Any, on_rerun: Callable[[Rerun], None] | None = None) -> None:
        self.client = client
        self._address = str(client.scheduler.address)
        self.on_rerun = on_rerun
        self.reruns: list[Rerun] = []
        self._names: dict[str, str] = {}  # dask key -> trial name, while its result is awaited
        self._lock = threading.Lock()
        client.subscribe_topic("all", self._on_event)

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        key = f"sctd-trial-{uuid.uuid4().hex}"
        name = str(getattr(fn, "name", key))
        with self._lock:
            self._names[key] = name
        remote = self.client.submit(fn, *args, key=key, pure=False, **kwargs)
        out: Future = Future()

        def settle(f: Any) -> None:  # on a thread of the client's, once the task ended
            with self._lock:
                self._names.pop(key, None)
            if out.done():  # cancelled by us
                return
            with suppress(InvalidStateError):  # cancelled by us meanwhile
                if f.status == "cancelled":  # not by us: the cluster dropped it
                    out.set_exception(ClusterError(f"--scheduler {self._address}: trial {name} was dropped "
                                                   "by the cluster (the scheduler closed or restarted?)"))
                    return
                try:
                    result = f.result()
                except Exception as e:  # the trial's own error, or its result lost on the way
                    out.set_exception(_explained(e, self._address, name))
                    return
                out.set_result(result)

        def cancel(f: Future) -> None:
            if f.cancelled():
                remote.cancel()

        out.add_done_callback(cancel)
        remote.add_done_callback(settle)
        return out

    def _on_event(self, event: tuple[float, dict[str, Any]]) -> None:
        msg = event[1]
        if not isinstance(msg, dict) or msg.get("action") != "remove-worker":
            return
        keys = set(msg.get("processing-tasks", ())) | set(msg.get("lost-computed-tasks", ()))
        with self._lock:
            mine = tuple(sorted(self._names[k] for k in keys if k in self._names))
        if not mine:
            return
        r = Rerun(str(msg.get("worker", "?")), mine)
        self.reruns.append(r)
        if self.on_rerun is not None:
            self.on_rerun(r)
        else:
            log.warning("%s", r)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        with suppress(Exception):  # a scheduler gone already: nothing to unsubscribe from
            self.client.unsubscribe_topic("all")
        self.client.close()


def connect(address: str, tls: TlsFiles | None = None, timeout: float = CONNECT_TIMEOUT,
            on_rerun: Callable[[Rerun], None] | None = None) -> ClusterExecutor:
    """An executor on the scheduler at ``address`` that has at least one worker.

    Raises
    ------
    ClusterError
        The address is refused (:func:`check_address`), the scheduler does not answer
        within ``timeout`` s, or it has no worker within ``timeout`` s.
    """
    address = check_address(address, tls)
    security = tls.security() if tls is not None else None
    from distributed import Client

    how = "with mutual TLS" if tls is not None else "over plain TCP"
    try:
        client = Client(address, security=security, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as e:
        raise ClusterError(f"--scheduler {address}: no Dask scheduler answered within {timeout:g} s "
                           f"(tried to connect {how}): {e}") from None
    try:
        client.wait_for_workers(1, timeout=timeout)
    except (OSError, TimeoutError):
        client.close()
        raise ClusterError(f"--scheduler {address}: the scheduler answered but had no worker within "
                           f"{timeout:g} s (start some: sctd cluster worker {address})") from None
    return ClusterExecutor(client, on_rerun)


def add_scheduler_arguments(p: argparse.ArgumentParser, role: str) -> None:
    """``--scheduler`` and its TLS flags (``sctd eval``, ``sctd learner``); a client's
    certificate from a ``sctd certs`` folder is ``role``'s."""
    g = p.add_argument_group("trials on a Dask cluster (docs/cluster.md)")
    g.add_argument("--scheduler", metavar="ADDR",
                   help="run the lockstep trials on this Dask scheduler's workers (tcp://127.0.0.1:PORT, "
                        "or tls://HOST:PORT with certificates); default: local processes")
    g.add_argument("--certs", metavar="DIR",
                   help=f"a sctd certs --out folder: its CA and the {role} key pair, for tls://")
    g.add_argument("--tls-ca", metavar="PEM", help="the CA that signed the cluster's certificates")
    g.add_argument("--tls-cert", metavar="PEM", help="this client's certificate")
    g.add_argument("--tls-key", metavar="PEM", help="this client's key")


def executor_from_args(args: argparse.Namespace, role: str,
                       on_rerun: Callable[[Rerun], None] | None = None) -> ClusterExecutor | None:
    """The cluster's executor the flags of :func:`add_scheduler_arguments` name (None
    without ``--scheduler``); :class:`ClusterError` when it cannot be used."""
    tls = tls_files(args.tls_ca, args.tls_cert, args.tls_key, args.certs, role)
    if args.scheduler is None:
        if tls is not None:
            raise ClusterError("--certs/--tls-*: only with --scheduler")
        return None
    return connect(args.scheduler, tls, on_rerun=on_rerun)


def check_listen(host: str, tls: TlsFiles | None) -> None:
    """Refuse to listen on a non-loopback ``host`` without TLS."""
    if tls is None and not is_loopback(host):
        raise ClusterError(f"--host {host}: plain TCP listens on loopback only (127.0.0.1); "
                           "on another address use --certs DIR (mutual TLS with sctd certs)")


@contextmanager
def local_cluster(n: int, tls: TlsFiles | None = None) -> Iterator[str]:
    """A scheduler in this process and ``n`` single-threaded worker processes, all on
    127.0.0.1 with no dashboard; yields the scheduler's address, closes them on exit."""
    import dask
    from distributed import LocalCluster

    with dask.config.set(QUIET_HTTP), LocalCluster(
            n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
            protocol="tls://" if tls else "tcp://", security=tls.security() if tls else None,
            dashboard_address=LOCAL_HTTP) as lc:
        yield str(lc.scheduler_address)


async def serve_scheduler(host: str, port: int, tls: TlsFiles | None,
                          ready: Callable[[str], None], stop: asyncio.Event) -> None:
    """Run a scheduler on ``host:port`` (0: any free port) until ``stop``; ``ready(address)``
    once it listens. No dashboard; its HTTP server binds 127.0.0.1 with no routes."""
    import dask
    from distributed import Scheduler

    check_listen(host, tls)
    with dask.config.set(QUIET_HTTP):
        async with Scheduler(host=host, port=port, protocol="tls" if tls else "tcp",
                             security=tls.security() if tls else None, dashboard=False,
                             dashboard_address=LOCAL_HTTP) as s:
            ready(s.address)
            await stop.wait()


async def serve_workers(scheduler: str, n: int, host: str, tls: TlsFiles | None,
                        ready: Callable[[list[str]], None], stop: asyncio.Event) -> None:
    """Run ``n`` single-threaded worker processes (each behind a nanny, which starts it
    again if it dies) for ``scheduler`` until ``stop``; ``ready(addresses)`` once they
    joined."""
    import dask
    from distributed import Nanny

    scheduler = check_address(scheduler, tls, "ADDR")
    check_listen(host, tls)
    with dask.config.set(QUIET_HTTP):
        nannies = [Nanny(scheduler, nthreads=1, host=host, protocol="tls" if tls else "tcp",
                         security=tls.security() if tls else None, dashboard_address=LOCAL_HTTP)
                   for _ in range(n)]
        try:
            await asyncio.gather(*(nn.start() for nn in nannies))
            ready([str(nn.worker_address) for nn in nannies])
            await stop.wait()
        finally:
            await asyncio.gather(*(nn.close() for nn in nannies), return_exceptions=True)


__all__ = [
    "ClusterError",
    "ClusterExecutor",
    "Rerun",
    "TlsFiles",
    "add_scheduler_arguments",
    "check_address",
    "connect",
    "executor_from_args",
    "local_cluster",
    "serve_scheduler",
    "serve_workers",
    "tls_files",
]
