"""The skill queryables, served by a child process of the daemon.

A hot-swap bundle is up to :data:`~sctd.skill.loader.MAX_BUNDLE_BYTES` (8 MiB) of query
payload, and the only way to read a Zenoh payload from Python is to copy it out of
Zenoh's buffer (``ZBytes.to_bytes``) in one C call that holds the GIL: 1-2 ms for 8 MiB
on a quiet machine, 7 ms on a loaded one, time in which the daemon's tick thread cannot
run. So the payload is never in the daemon's process. Its child, the skill server
(``python -m sctd.runtime.skillserver``), owns both queryables, ``sctd/<robot>/skill``
and ``sctd/<robot>/skill/swap``, on a Zenoh session of its own:

- opened from the daemon's own ``--listen`` / ``--connect`` / ``--zenoh-config``
  settings (:func:`~sctd.wire.session.helper_config`): it connects where the daemon
  connects and listens (and, under the loopback defaults, listens on an ephemeral
  loopback port, so that a peer told of it by gossip can open the link too), and so
  acts on the network as the daemon (same mode, credentials and certificates: an access policy that lets the
  daemon answer these keys lets its skill server answer them);
- validating each bundle in a grandchild (:class:`~sctd.runtime.worker.BundleWorker`),
  which keeps the containment boundary for hostile bundles: a zip bomb, a nesting too
  deep, a parser that crashes or hangs costs that process (refused, and replaced), never
  the skill server or the daemon;
- handing the validated :class:`~sctd.skill.Skill` to the daemon over a socket pair
  (:mod:`sctd.runtime.frames`: the model arrays out of band, received by the daemon into
  memory maps with the GIL released), and replying only once the daemon says the swap
  landed at a tick boundary, with the FSM state it landed in, or why it did not;
- asking the daemon for each summary (``skill_summary`` of the active skill plus its
  FSM state, worked out in the daemon as before), so that a summary is of the skill
  that runs;
- with a skill set, passing on the member a swap names (the selector parameter
  ``member``: ``skill/swap?member=drawer``), which the daemon checks, and serving a
  member's kept bundle on ``skill/bundle?member=NAME``.

Every query gets exactly one reply; refusals are error replies ``{error: ...}`` (``<file>:
<field>: <problem>``, ``<bundle>: ...`` when no file is to blame), each reported to the
daemon, which logs and counts it (``status.counters.swaps_refused``). One swap at a
time: the skill server takes one bundle after the other. The daemon's side
(:class:`SkillServer`) builds the new skill's engine (KD-trees, which release the GIL)
and its object rings on a thread of its own, hands them to the tick through its
one-slot mailbox, and frees the replaced skill on that thread too, off the tick thread.

The skill server exits when the daemon closes its end of the link (it ignores SIGINT
and SIGTERM: its life is the daemon's). When it dies otherwise (killed, crashed), a swap
it was serving goes unanswered (the asker's ``get`` ends without a reply, at the latest
at its timeout), the daemon keeps ticking and starts another skill server, whose
queryables then answer again.
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import msgpack
import zenoh

from ..skill import Skill, SkillError
from ..skill.loader import MAX_BUNDLE_BYTES
from ..wire import Keys
from ..wire.client import MEMBER
from ..wire.session import MSGPACK, SessionSettings, close_session, helper_config
from . import bundles, frames
from .worker import WHERE, BundleWorker

log = logging.getLogger("sctd.skillserver")

READY_WAIT = 10.0  # s the skill server waits to be connected to the daemon before it says ready
BUNDLE_PARAMETER = "bundle"  # ``get sctd/<robot>/skill?bundle``: the active bundle, not the summary
MEMBER_PARAMETER = MEMBER  # ``skill/swap?member=NAME``: the skill set's member a swap replaces
BUNDLE_VERSION = 1  # of that reply's map
SUMMARY_WAIT = 10.0  # s the skill server waits for the daemon's summary
SWAP_WAIT = 60.0  # s it waits for the daemon's answer to a swap (the daemon's own limit is 5 s)
RESTART_MIN, RESTART_MAX = 0.5, 5.0  # s between restarts of a skill server that died
CLOSE_WAIT = 3.0  # s a closing skill server has to exit on its own


@dataclass(frozen=True)
class ServerOptions:
    """What a skill server is started with (passed to it as JSON)."""

    robot: str
    session: SessionSettings
    swap_on_skill_key: bool  # wire contract v1: a bundle sent to ``skill`` swaps too
    daemon_zid: str = ""  # the daemon's session: the skill server is ready once it reaches it
    bundles: str = ""  # the folder the active skill's bundle is kept in (sctd.runtime.bundles)

    def to_json(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> ServerOptions:
        raw = json.loads(text)
        ses = raw.pop("session")

        def endpoints(v: list[str] | None) -> tuple[str, ...] | None:
            return None if v is None else tuple(v)
        return cls(session=SessionSettings(endpoints(ses["listen"]), endpoints(ses["connect"]),
                                           ses["config_file"]), **raw)


def _reply(body: dict[str, Any]) -> bytes:
    """A skill-queryable reply (summary, swap result or error) as a msgpack map."""
    return msgpack.packb(body, use_bin_type=True)


# --- the daemon's side -------------------------------------------------------------------


class SkillServer:
    """The daemon's end of its skill server: starts it (again, whenever it dies) and
    answers it on a thread of its own. A context manager.

    Parameters
    ----------
    options : ServerOptions
    summary : callable
        ``summary() -> dict``: the active skill's summary with its FSM state.
    swap : callable
        ``swap(skill, member) -> dict``: install ``skill`` at a tick boundary (in the
        place of the skill set's ``member``, or None) and return ``{state, in_use,
        [member]}`` (:meth:`.swap.SkillSwap.answer`); raise
        :class:`~sctd.skill.SkillError` to refuse it.
    refused : callable
        ``refused(error)``: a query was refused with this error reply.
    stop : threading.Event, optional
        Once set, a skill server that dies is not replaced.
    between_ticks : callable, optional
        ``between_ticks()`` returns when the tick thread has a period's idle time ahead:
        a received skill is unpickled, and a summary worked out, from then on.
    rt_priority : int
        The daemon's tick priority (0: none). The link thread, which reads each skill
        from the link, and the thread that compiles and installs it run at SCHED_FIFO
        two below it (when permitted): a thread of normal priority that holds the GIL
        can be preempted by any other process while it holds it, and the tick then
        waits for the GIL until that thread runs again (tens of ms on a loaded
        machine). What they start (processes, threads) is not real-time.
    """

    def __init__(self, options: ServerOptions, summary: Callable[[], dict[str, Any]],
                 swap: Callable[[Skill, str | None], dict[str, Any]], refused: Callable[[str], None],
                 stop: threading.Event | None = None,
                 between_ticks: Callable[[], None] | None = None, rt_priority: int = 0):
        self.options = options
        self._between_ticks = between_ticks if between_ticks is not None else (lambda: None)
        self.priority = max(1, rt_priority - 2) if rt_priority > 0 else 0
        self._summary, self._swap, self._refused = summary, swap, refused
        self._stop = stop if stop is not None else threading.Event()
        self._closing = threading.Event()
        self._ready = threading.Event()
        self._write_lock = threading.Lock()
        self._proc: subprocess.Popen | None = None
        self._sock: socket.socket | None = None
        self._swaps: list[threading.Thread] = []
        self._thread = threading.Thread(target=self._run, name="sctd-skill-link", daemon=True)

    def __enter__(self) -> SkillServer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def wait_ready(self, timeout: float) -> bool:
        """Wait until a skill server has declared the queryables and reached the daemon."""
        return self._ready.wait(timeout)

    def close(self) -> None:
        """Stop the skill server (it exits when the link closes; killed after
        :data:`CLOSE_WAIT` s) and the threads; a swap under way is answered first."""
        self._closing.set()
        for t in list(self._swaps):
            t.join(timeout=10.0)
        proc, sock = self._proc, self._sock
        if sock is not None:
            try:  # the skill server's cue to close its session and exit
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        self._thread.join(timeout=CLOSE_WAIT + 2.0)
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()

    # --- the link thread ----------------------------------------------------------------

    def _run(self) -> None:
        _realtime(self.priority)
        delay = RESTART_MIN
        while not self._done():
            started = time.monotonic()
            try:
                proc, sock = self._spawn()
            except OSError as e:
                log.error("cannot start the skill server: %s", e)
            else:
                self._serve(proc, sock)
                code = self._reap(proc, sock)
                if self._done():
                    break
                log.warning("the skill server (process %d) exited with code %s; starting another",
                            proc.pid, code)
            self._ready.clear()
            lasted = time.monotonic() - started
            delay = RESTART_MIN if lasted > 10 * RESTART_MAX else min(2 * delay, RESTART_MAX)
            self._closing.wait(delay)

    def _done(self) -> bool:
        return self._closing.is_set() or self._stop.is_set()

    def _spawn(self) -> tuple[subprocess.Popen, socket.socket]:
        ours, theirs = frames.pair()
        with theirs:  # its stdout is our stderr (fd 2): nothing it prints reaches our stdout
            proc = subprocess.Popen(
                [sys.executable, "-m", "sctd.runtime.skillserver", str(theirs.fileno()),
                 self.options.to_json()],
                stdin=subprocess.DEVNULL, stdout=2, pass_fds=[theirs.fileno()])
        self._proc, self._sock = proc, ours
        return proc, ours

    def _reap(self, proc: subprocess.Popen, sock: socket.socket) -> int | None:
        try:  # closing: it exits on its own once its session is closed
            code = proc.wait(CLOSE_WAIT if self._closing.is_set() else 0.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            code = proc.wait()
        sock.close()
        return code

    def _serve(self, proc: subprocess.Popen, sock: socket.socket) -> None:
        """Answer the skill server until the link closes."""
        while True:
            try:
                kind, rid, body = frames.receive(sock, self._between_ticks)
            except (EOFError, OSError, ValueError):
                return
            except Exception:  # an unpicklable message: the stream is lost
                log.exception("unreadable message from the skill server")
                return
            if kind == "swap":
                t = threading.Thread(target=self._answer_swap, args=(sock, rid, body),
                                     name="sctd-swap", daemon=True)
                self._swaps = [s for s in self._swaps if s.is_alive()] + [t]
                t.start()
            elif kind == "summary":
                try:
                    self._between_ticks()
                    self._answer(sock, rid, True, self._summary())
                except Exception as e:  # the skill server must get its answer
                    log.exception("summary failed")
                    self._answer(sock, rid, False, f"{WHERE}: {type(e).__name__}: {e}")
            elif kind == "refused":
                self._refused(body)
            elif kind == "ready":
                log.info("skill queryables served by process %d (%s)", proc.pid, body)
                self._ready.set()

    def _answer_swap(self, sock: socket.socket, rid: int, body: tuple[Skill, str | None]) -> None:
        _realtime(self.priority)
        skill, member = body
        try:
            landed = self._swap(skill, member)
        except SkillError as e:
            self._answer(sock, rid, False, str(e))
        except Exception as e:  # every swap gets its answer
            log.exception("swap failed")
            self._answer(sock, rid, False, f"{WHERE}: {type(e).__name__}: {e}")
        else:
            self._answer(sock, rid, True, landed)

    def _answer(self, sock: socket.socket, rid: int, ok: bool, body: Any) -> None:
        with self._write_lock:
            try:
                frames.send(sock, ("answer", rid, (ok, body)))
            except OSError:  # it died, or is closing: it answers nothing more
                pass


def _realtime(priority: int) -> None:
    """The calling thread at SCHED_FIFO ``priority`` (0 or not permitted: unchanged),
    reset on fork: the processes and threads it starts get normal scheduling."""
    if priority <= 0:
        return
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
    except (OSError, AttributeError):
        pass


# --- the skill server's side ---------------------------------------------------------------


class _Link:
    """The skill server's end of the link to the daemon: messages out, numbered requests
    answered in."""

    def __init__(self, sock: socket.socket):
        self.sock = sock
        self.closed = threading.Event()
        self._write_lock = threading.Lock()
        self._lock = threading.Lock()
        self._ids = itertools.count(1)
        self._waiting: dict[int, list[Any]] = {}  # request -> [event, answer]
        self._reader = threading.Thread(target=self._read, name="skill-link", daemon=True)
        self._reader.start()

    def send(self, kind: str, body: Any = None, rid: int = 0) -> None:
        with self._write_lock:
            frames.send(self.sock, (kind, rid, body))

    def call(self, kind: str, body: Any, timeout: float) -> tuple[bool, Any]:
        """Ask the daemon: its answer ``(ok, body)``; ``(False, error)`` when it did not
        answer within ``timeout`` s or is gone."""
        rid = next(self._ids)
        slot: list[Any] = [threading.Event(), None]
        with self._lock:
            if self.closed.is_set():
                return False, f"{WHERE}: the daemon is stopping"
            self._waiting[rid] = slot
        try:
            self.send(kind, body, rid)
            if not slot[0].wait(timeout):
                return False, f"{WHERE}: the daemon did not answer within {timeout:g} s"
        except OSError:
            return False, f"{WHERE}: the daemon is stopping"
        finally:
            with self._lock:
                self._waiting.pop(rid, None)
        return slot[1] if slot[1] is not None else (False, f"{WHERE}: the daemon is stopping")

    def _read(self) -> None:
        try:
            while True:
                _kind, rid, answer = frames.receive(self.sock)
                with self._lock:
                    slot = self._waiting.get(rid)
                if slot is not None:
                    slot[1] = answer
                    slot[0].set()
        except Exception:  # EOF: the daemon closed the link (or died)
            pass
        finally:
            with self._lock:
                self.closed.set()
                for slot in self._waiting.values():
                    slot[0].set()


class _Queries:
    """The three queryables' handlers (on Zenoh's threads, in the skill server)."""

    def __init__(self, keys: Keys, link: _Link, worker: BundleWorker, swap_on_skill_key: bool,
                 bundles: str = ""):
        self.keys, self.link, self.worker = keys, link, worker
        self.swap_on_skill_key = swap_on_skill_key
        self.bundles = bundles
        self._swap_lock = threading.Lock()

    def on_skill(self, query: zenoh.Query) -> None:
        self._on_query(query, self.keys.skill)

    def on_swap(self, query: zenoh.Query) -> None:
        self._on_query(query, self.keys.skill_swap)

    def on_bundle(self, query: zenoh.Query) -> None:
        """``skill/bundle``: the active bundle; it swaps nothing, so a payload is refused
        without counting as a refused swap."""
        with query:
            try:
                if query.payload is not None and len(query.payload) > 0:
                    query.reply_err(_reply({"error": f"{self.keys.skill_bundle} is read-only: "
                                                     f"ask with no payload"}), encoding=MSGPACK)
                    return
                ok, body = self.link.call("summary", None, SUMMARY_WAIT)
                if ok:
                    ok, body = self._bundle(body, query.parameters.get(MEMBER_PARAMETER))
                if ok:
                    query.reply(self.keys.skill_bundle, _reply(body), encoding=MSGPACK)
                else:
                    query.reply_err(_reply({"error": body}), encoding=MSGPACK)
            except Exception as e:  # every query gets a reply
                log.exception("bundle query failed")
                query.reply_err(_reply({"error": f"{WHERE}: {type(e).__name__}: {e}"}), encoding=MSGPACK)

    def _on_query(self, query: zenoh.Query, key: str) -> None:
        # The query ends (the asker stops waiting) when it is dropped: on leaving this
        # block, not whenever the last reference to it goes.
        with query:
            try:
                self._answer(query, key)
            except Exception as e:  # every query gets a reply, whatever went wrong
                log.exception("skill query failed")
                self._refuse(query, f"{WHERE}: {type(e).__name__}: {e}")

    def _refuse(self, query: zenoh.Query, error: str) -> None:
        """Every refusal, whatever its cause, is one error reply ``{"error": text}``
        (``text`` reads ``<file>: <field>: <problem>``), reported to the daemon."""
        try:
            self.link.send("refused", error)
        except OSError:  # the daemon is gone: the reply still goes out
            pass
        query.reply_err(_reply({"error": error}), encoding=MSGPACK)

    def _answer(self, query: zenoh.Query, key: str) -> None:
        """``skill``: the summary (and, with ``swap_on_skill_key``, a swap: wire contract
        v1); ``skill/swap``: a swap only."""
        payload = query.payload
        empty = payload is None or len(payload) == 0
        if key == self.keys.skill and empty:
            ok, body = self.link.call("summary", None, SUMMARY_WAIT)
            if ok and query.parameters.get(BUNDLE_PARAMETER) is not None:
                ok, body = self._bundle(body, query.parameters.get(MEMBER_PARAMETER))
            if ok:
                query.reply(key, _reply(body), encoding=MSGPACK)
            else:
                self._refuse(query, body)
            return
        if empty:
            self._refuse(query, f"{WHERE}: {key} swaps skills: send a bundle (the summary is on "
                                f"{self.keys.skill})")
            return
        if key == self.keys.skill and not self.swap_on_skill_key:
            self._refuse(query, f"{WHERE}: swaps go to {self.keys.skill_swap} (with a Zenoh "
                                f"config, {self.keys.skill} answers summaries only)")
            return
        assert payload is not None
        if len(payload) > MAX_BUNDLE_BYTES:
            # refused before it is copied out of Zenoh's buffer
            self._refuse(query, f"{WHERE}: bundle of {len(payload)} bytes exceeds {MAX_BUNDLE_BYTES}")
            return
        with self._swap_lock:  # one swap at a time
            try:
                skill = self.worker.skill(payload.to_bytes())
            except SkillError as e:
                self._refuse(query, str(e))
                return
            ok, landed = self.link.call("swap", (skill, query.parameters.get(MEMBER_PARAMETER)), SWAP_WAIT)
        if not ok:
            self._refuse(query, landed)
            return
        if self.bundles:
            try:
                bundles.keep(self.bundles, skill.id, payload.to_bytes(), pinned=landed.get("in_use", ()))
            except OSError as e:  # the swap stands; only a view's fetch of it will fail
                log.error("cannot keep the bundle of %s: %s", skill.id, e)
        reply = {"ok": True, "id": skill.id, "name": skill.name, "state": landed["state"]}
        if "member" in landed:
            reply["member"] = landed["member"]
        query.reply(key, _reply(reply), encoding=MSGPACK)

    def _bundle(self, summary: dict[str, Any], member: str | None = None) -> tuple[bool, Any]:
        """``skill/bundle`` (and ``skill?bundle``): the active skill's bundle as kept, with
        its id, name and FSM state (``{v, id, name, state, bundle}``), or why not. With
        ``member``, the running skill set's member (or teleoperation) of that name
        (``state``: the active state while it runs, else null)."""
        if member is not None:
            found = _set_skill(summary, member)
            if isinstance(found, str):
                return False, found
            running = found["id"] == summary.get("id")
            summary = {**found, "state": summary.get("state") if running else None}
        data = bundles.kept(self.bundles, str(summary.get("id", "")))
        if data is None:
            which = "the active skill" if member is None else f"{MEMBER_PARAMETER} {member}"
            return False, f"{WHERE}: the bundle of {which} {summary.get('id')} is not kept"
        return True, {"v": BUNDLE_VERSION, "id": summary.get("id"), "name": summary.get("name"),
                      "state": summary.get("state"), "bundle": data}


def _set_skill(summary: dict[str, Any], name: str) -> dict[str, Any] | str:
    """The running skill set's member (or teleoperation) ``name`` as the summary has it
    (``{id, name, object, ...}``), or why not."""
    the_set = summary.get("set")
    if not isinstance(the_set, dict):
        return f"{WHERE}: {MEMBER_PARAMETER}={name}: the daemon runs one skill, not a skill set"
    skills = [*the_set.get("members", []), the_set.get("teleop") or {}]
    for s in skills:
        if s.get("name") == name:
            return s
    names = ", ".join(str(s.get("name")) for s in skills)
    return f"{WHERE}: {MEMBER_PARAMETER}={name}: no such skill in the running set (its skills: {names})"


def _wait_connected(session: zenoh.Session, daemon_zid: str, link: _Link, timeout: float) -> bool:
    """Wait until the session reaches the daemon's (directly, or through a router), or
    the daemon closes the link."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and not link.closed.is_set():
        peers = {str(z) for z in session.info.peers_zid()}
        if daemon_zid in peers or not daemon_zid or any(True for _ in session.info.routers_zid()):
            return True
        time.sleep(0.01)
    return False


def main(argv: list[str]) -> int:
    """The skill server: queryables on a session of its own, answered with the daemon
    over the socket ``argv[0]`` (options: ``argv[1]``), until the daemon closes it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # stopped by the daemon closing the link
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stderr)
    link = _Link(frames.from_fd(int(argv[0])))
    opts = ServerOptions.from_json(argv[1])
    try:
        session = zenoh.open(helper_config(opts.session))
    except (ValueError, zenoh.ZError) as e:
        log.error("cannot open Zenoh session: %s", e)
        return 1
    keys = Keys(opts.robot)
    try:
        with BundleWorker() as worker:
            queries = _Queries(keys, link, worker, opts.swap_on_skill_key, opts.bundles)
            with session.declare_queryable(keys.skill, queries.on_skill), \
                    session.declare_queryable(keys.skill_swap, queries.on_swap), \
                    session.declare_queryable(keys.skill_bundle, queries.on_bundle):
                if not _wait_connected(session, opts.daemon_zid, link, READY_WAIT) \
                        and not link.closed.is_set():
                    log.warning("not connected to the daemon's session after %g s; serving anyway",
                                READY_WAIT)
                if not link.closed.is_set():
                    link.send("ready", {"zid": str(session.zid())})
                link.closed.wait()
    except OSError:  # the daemon closed the link while we said ready
        pass
    finally:
        close_session(session)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
