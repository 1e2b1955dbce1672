"""``sctd view``: the live view's process, an observer of the robot's keys.

It subscribes, and declares nothing else but one querier on ``skill`` (the active
bundle, ``skill?bundle``, whenever the status names another skill id): no publisher,
no querier on ``input``, ``target``, ``skill/swap`` or any other key that commands
(:data:`READS` lists what it reads). Deployed across hosts it runs with the
``sctd-observer`` role's certificate.

**Decimation.** The 1 kHz keys (``state``, ``target``) arrive into rings of one
(Zenoh's ``RingChannel``: the newest wins, nothing queues), read at the drawing rate
(:data:`RATE`, 30 Hz); the slower ones (objects 50 Hz, status 20 Hz, scene 10 Hz,
inputs) keep their newest message per key in a callback. Nothing is drawn more often
than the view's rate, whatever the robot publishes.
"""

from __future__ import annotations

import logging
import threading
import time

import zenoh

from sctd.wire import Keys, client, codec

from .live import LiveView, Snapshot

log = logging.getLogger("sctd.view")
RATE = 30.0  # Hz the view draws at
FETCH_RETRY = 2.0  # s before the active bundle is asked for again after a failure
READS = ("state", "target", "status", "scene", "objects/<name>", "input/*")


class Feed:
    """The robot's keys as the view reads them (a context manager: undeclares them).

    Parameters
    ----------
    session : zenoh.Session
    keys : Keys
    objects : iterable of str
        The objects whose poses to read (by name: an observer may not subscribe a
        wildcard it is not granted).
    """

    def __init__(self, session: zenoh.Session, keys: Keys, objects):
        self.session, self.keys = session, keys
        self._lock = threading.Lock()
        self._objects: dict[str, list] = {}
        self._inputs: dict[str, tuple] = {}
        self._status: dict | None = None
        self._scene: dict | None = None
        self.dropped = 0  # messages that did not decode
        self._last_state: tuple[list | None, list | None] = (None, None)
        self._last_target: dict | None = None
        ring = zenoh.handlers.RingChannel
        self._state = session.declare_subscriber(keys.state, ring(1))
        self._target = session.declare_subscriber(keys.target, ring(1))
        self._subs = [session.declare_subscriber(keys.status, self._on("status")),
                      session.declare_subscriber(keys.scene, self._on("scene")),
                      session.declare_subscriber(keys.input("*"), self._on_input)]
        self._subs += [session.declare_subscriber(keys.objects(n), self._on_object(n))
                       for n in sorted(objects)]

    def _on(self, what: str):
        def store(sample: zenoh.Sample) -> None:
            try:
                msg = codec.unpack_map(sample.payload.to_bytes())
            except Exception:  # any bad message: counted, never drawn
                self.dropped += 1
                return
            with self._lock:
                setattr(self, f"_{what}", msg)
        return store

    def _on_object(self, name: str):
        def store(sample: zenoh.Sample) -> None:
            try:
                pose = codec.decode_object(sample.payload.to_bytes()).pose
            except Exception:
                self.dropped += 1
                return
            with self._lock:
                self._objects[name] = list(pose)
        return store

    def _on_input(self, sample: zenoh.Sample) -> None:
        device = str(sample.key_expr).rsplit("/", 1)[-1]
        try:
            msg = codec.decode_input(sample.payload.to_bytes())
        except Exception:
            self.dropped += 1
            return
        with self._lock:
            if len(self._inputs) < 16 or device in self._inputs:  # a bound on what a key can cost
                self._inputs[device] = (list(msg.u), msg.stamp)

    def snapshot(self) -> Snapshot:
        """The newest of everything (the 1 kHz rings emptied)."""
        snap = Snapshot(t=time.monotonic())
        state, target = self._state.try_recv(), self._target.try_recv()
        try:
            if state is not None:
                msg = codec.decode_state(state.payload.to_bytes())
                self._last_state = (list(msg.pose), msg.q)
            if target is not None:
                self._last_target = codec.decode_target(target.payload.to_bytes())
        except Exception:
            self.dropped += 1
        snap.pose, snap.q = self._last_state
        snap.target = self._last_target
        with self._lock:
            snap.objects = dict(self._objects)
            snap.inputs = dict(self._inputs)
            snap.status, snap.scene = self._status, self._scene
        return snap

    def close(self) -> None:
        for s in (self._state, self._target, *self._subs):
            s.undeclare()

    def __enter__(self) -> Feed:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_view(session: zenoh.Session, keys: Keys, view: LiveView, stop: threading.Event,
             rate: float = RATE) -> None:
    """Draw the robot's keys on ``view`` at ``rate`` until ``stop`` is set."""
    task = view.task
    objects = set(task.scene.bodies) if task is not None else set()
    with Feed(session, keys, objects) as feed:
        skill_id, retry = None, 0.0
        period, due = 1.0 / rate, time.monotonic()
        while not stop.is_set():
            snap = feed.snapshot()
            wanted = (snap.status or {}).get("skill")
            if wanted and wanted != skill_id and snap.t >= retry:
                got = _fetch(session, keys, view, wanted)
                skill_id, retry = (got, 0.0) if got else (skill_id, snap.t + FETCH_RETRY)
            view.draw(snap)
            due += period
            stop.wait(max(0.0, due - time.monotonic()))


def _fetch(session: zenoh.Session, keys: Keys, view: LiveView, wanted: str) -> str | None:
    """Fetch the active bundle and draw its skill; its id, or None when it failed."""
    from sctd.skill import skill_from_bundle

    got = client.active_bundle(session, keys, timeout=5.0, find=2.0)
    if isinstance(got, str):
        log.warning("cannot fetch the active skill %s: %s", wanted, got)
        return None
    bundle, meta = got
    view.set_skill(skill_from_bundle(bundle))
    log.info("drawing skill %s@%s", meta.get("name"), meta.get("id"))
    return str(meta.get("id"))
