"""The page of ``sctd try`` and its socket, on 127.0.0.1 (``docs/try.md``).

One port serves the page (``GET /``) and its WebSocket (``/ws``), with the
``websockets`` package (already installed with Viser, which serves its own pages with
it) on an asyncio loop in a thread of its own. A page's messages are JSON:

- ``{"type": "input", "seq", "source", "axes", "buttons"}``: a raw reading, handed to
  the :class:`~sctd_services.input.page.PageGate`, which checks, maps and publishes it;
- ``{"type": "stale", "why": "hidden"|"blur"}`` and ``{"type": "resume"}``: the page was
  hidden or lost focus, and is back;
- ``{"type": "start", "task", "condition"}`` and ``{"type": "abort"}``: the trial,
  handed to ``on_request`` (the controller's only; an observer's are refused); a server
  made with other ``requests`` (``sctd study run``'s) hands those on the same way.

A socket opened on ``/ws?watch`` is a **watcher** (``sctd study run``'s experimenter's
page): never the controller, its input ignored, its requests handed to ``on_watch``.

**Off this machine, mutual TLS and roles.** By default the server listens on 127.0.0.1
only. Given a TLS context (:func:`page_tls`, from a folder of ``sctd certs``) it serves
HTTPS and WSS, on any address, and every browser must present a client certificate of
the deployment's CA; its common name is its role (docs/deploy.md): ``sctd-input`` and
``sctd-operator`` may drive (the first such page is the controller, as on loopback),
``sctd-observer`` only watches (a watcher, whatever the path), and any other role's
socket is closed with a policy violation before anything is read from it.

Every :data:`STATE_PERIOD` the server sends each page ``{"type": "state", ...}``: its role,
the gate's counters and last message, and whatever ``state()`` returns (the trial, the
daemon's status). A closed socket is the gate's ``disconnect`` (the arm stops).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import ssl
import threading
from collections.abc import Callable, Mapping
from http import HTTPStatus
from importlib import resources
from pathlib import Path
from typing import Any

from sctd_services.input.page import PageGate

STATE_PERIOD = 0.1  # s between state messages to each page
MAX_MESSAGE = 4096  # bytes: a reading is about 150
PING = 2.0  # s between the server's pings (a socket that stops answering closes after 2 more)
DRIVERS = ("sctd-input", "sctd-operator")  # the certificates' roles that may drive from a page
WATCHERS = ("sctd-observer",)  # the roles that only watch
POLICY_VIOLATION = 1008  # the WebSocket close code for a role the page does not serve


class PageTLSError(ValueError):
    """A TLS folder that cannot serve the page (the message names the file and what)."""


def page_tls(folder: str | Path) -> ssl.SSLContext:
    """The server's TLS context from a folder ``sctd certs`` wrote: the host's certificate
    ``sctd-router.pem`` and key (their subjectAltName names the host's addresses), and the
    CA ``ca.pem`` every browser's client certificate must be signed by (required).

    Raises
    ------
    PageTLSError
        A file missing or unreadable (the message names it).
    """
    d = Path(folder)
    cert, key, ca = d / "sctd-router.pem", d / "sctd-router-key.pem", d / "ca.pem"
    for f in (cert, key, ca):
        if not f.is_file():
            raise PageTLSError(f"{f}: no such file (make the folder with sctd certs: docs/deploy.md)")
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    try:
        ctx.load_cert_chain(cert, key)
        ctx.load_verify_locations(ca)
    except (ssl.SSLError, OSError) as e:
        raise PageTLSError(f"{d}: {cert.name}, {key.name} or {ca.name}: {e}") from None
    ctx.verify_mode = ssl.CERT_REQUIRED
    return ctx



def peer_role(ws: Any) -> str | None:
    """The common name of the client certificate of socket ``ws`` (None without TLS)."""
    obj = ws.transport.get_extra_info("ssl_object") if ws.transport is not None else None
    cert = obj.getpeercert() if obj is not None else None
    for rdn in (cert or {}).get("subject", ()):
        for key, value in rdn:
            if key == "commonName":
                return str(value)
    return None


PAGES: dict[str, tuple[str, str]] = {"/": ("sctd_services.tryout", "page.html"),
                                     "/index.html": ("sctd_services.tryout", "page.html"),
                                     "/input.js": ("sctd_services.tryout", "input.js"),
                                     "/input.css": ("sctd_services.tryout", "input.css")}
"""``sctd try``'s paths: the page and the input devices' script and style it loads."""
TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
         ".css": "text/css; charset=utf-8"}


class PageServer:
    """The page and its socket on ``127.0.0.1:port`` (0: a free one); a context manager.

    Parameters
    ----------
    gate : PageGate
    on_request : callable
        ``on_request(message)`` for a controller's ``start``/``abort``; returns None or a
        sentence saying why it is refused (sent back to that page).
    state : callable
        ``state()``: the shared part of every state message (plain data).
    hello : dict
        Sent to each page when it connects (the catalogue of tasks and skills).
    pages : mapping, optional
        URL path -> (package, file) served (default :data:`PAGES`).
    requests : tuple of str
        The message types handed to ``on_request`` (default ``start`` and ``abort``).
    on_watch : callable, optional
        ``on_watch(message)`` for a watcher's requests (module doc); None: refused.
    host : str
        The address to listen on (default 127.0.0.1).
    tls : ssl.SSLContext, optional
        :func:`page_tls`: HTTPS, WSS and client certificates by role (module doc).
    """

    def __init__(self, gate: PageGate, on_request: Callable[[dict], str | None],
                 state: Callable[[], dict], hello: dict, port: int = 0,
                 pages: Mapping[str, tuple[str, str]] = PAGES, requests: tuple[str, ...] = ("start", "abort"),
                 on_watch: Callable[[dict], str | None] | None = None, host: str = "127.0.0.1",
                 tls: ssl.SSLContext | None = None):
        self.gate, self.on_request, self.state, self.hello = gate, on_request, state, hello
        self.host, self.tls = host, tls
        self.pages, self.requests, self.on_watch = dict(pages), requests, on_watch
        self._ids = itertools.count(1)
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._stop: asyncio.Event | None = None
        self._error: BaseException | None = None
        self.port = port
        self._thread = threading.Thread(target=self._run, name="sctd-try-page", daemon=True)
        self._thread.start()
        self._ready.wait(10.0)
        if self._error is not None:
            raise self._error

    def __enter__(self) -> PageServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._stop is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(10.0)

    def _run(self) -> None:
        try:
            self._loop.run_until_complete(self._serve())
        except BaseException as e:  # (a port in use: raised in the caller's thread)
            self._error = e
            self._ready.set()
        finally:
            self._loop.close()

    async def _serve(self) -> None:
        from websockets.asyncio.server import serve

        self._stop = asyncio.Event()
        async with serve(self._handle, self.host, self.port, process_request=self._http,
                         max_size=MAX_MESSAGE, ping_interval=PING, ping_timeout=PING,
                         compression=None, ssl=self.tls) as server:
            self.port = next(iter(server.sockets)).getsockname()[1]
            self._ready.set()
            await self._stop.wait()

    def _http(self, connection: Any, request: Any) -> Any:
        """The pages (:data:`PAGES` or the server's own); the socket on ``/ws``; 404 for
        anything else."""
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        path = request.path.split("?", 1)[0]
        if path == "/ws":
            return None
        if path in self.pages:
            package, name = self.pages[path]
            body = resources.files(package).joinpath(name).read_bytes()
            headers = Headers([("Content-Type", TYPES[name[name.rfind("."):]]),
                               ("Content-Length", str(len(body))), ("Cache-Control", "no-store")])
            return Response(HTTPStatus.OK, "OK", headers, body)
        return connection.respond(HTTPStatus.NOT_FOUND, "not found\n")

    @property
    def url(self) -> str:
        """Where a browser opens the page."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'https' if self.tls is not None else 'http'}://{host}:{self.port}/"

    async def _handle(self, ws: Any) -> None:
        conn = next(self._ids)
        watcher = ws.request.path.split("?", 1)[-1] == "watch"
        if self.tls is not None:
            cn = peer_role(ws)
            if cn not in DRIVERS + WATCHERS:
                await ws.close(POLICY_VIOLATION, f"the role {cn} may not use this page")
                return
            watcher = watcher or cn in WATCHERS
        role = "watcher" if watcher else self.gate.connect(conn)
        sender = asyncio.create_task(self._send_state(ws, conn, watcher))
        try:
            await ws.send(json.dumps({"type": "hello", "role": role, **self.hello}))
            async for raw in ws:
                reply = self._watched(raw) if watcher else self._message(conn, raw)
                if reply is not None:
                    await ws.send(json.dumps({"type": "refused", "why": reply}))
        except Exception:  # a socket that broke: the same as one that closed
            pass
        finally:
            sender.cancel()
            if not watcher:
                self.gate.disconnect(conn)
            with contextlib.suppress(asyncio.CancelledError):
                await sender

    def _watched(self, raw: str | bytes) -> str | None:
        """One message from a watcher: its requests to ``on_watch``; its input ignored."""
        try:
            msg = json.loads(raw)
        except (ValueError, TypeError):
            return "not JSON"
        if not isinstance(msg, dict) or msg.get("type") in ("input", "stale", "resume"):
            return None
        return self.on_watch(msg) if self.on_watch is not None else "this page only watches"

    def _message(self, conn: int, raw: str | bytes) -> str | None:
        """One message from page ``conn``; a sentence for the page when it is refused."""
        try:
            msg = json.loads(raw)
        except (ValueError, TypeError):
            msg = None
        kind = msg.get("type") if isinstance(msg, dict) else None
        if kind == "input":
            self.gate.reading(conn, msg)
        elif kind == "stale":
            self.gate.pause(conn, str(msg.get("why")))
        elif kind == "resume":
            self.gate.resume(conn)
        elif kind in self.requests:
            if self.gate.role(conn) != "controller":
                return "this page is an observer: another page drives"
            return self.on_request(msg)
        else:
            self.gate.garbage(conn)
        return None

    async def _send_state(self, ws: Any, conn: int, watcher: bool = False) -> None:
        while True:
            role = "watcher" if watcher else self.gate.role(conn)
            msg = {"type": "state", "role": role, "gate": self.gate.report(), **self.state()}
            await ws.send(json.dumps(msg, default=str))
            await asyncio.sleep(STATE_PERIOD)
