"""``sctd view``: the live view's process, an observer of the robot's keys.

It subscribes, and declares nothing else but one querier on ``skill/bundle`` (the
active bundle, whenever the status names another skill id): no publisher,
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
from collections import Counter

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
        self.read: Counter[str] = Counter()  # messages read, by key under sctd/<robot>/
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
                self.read[what] += 1
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
                self.read[f"objects/{name}"] += 1
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
                self.read[f"input/{device}"] += 1

    def snapshot(self) -> Snapshot:
        """The newest of everything (the 1 kHz rings emptied)."""
        snap = Snapshot(t=time.monotonic())
        state, target = self._state.try_recv(), self._target.try_recv()
        try:
            if state is not None:
                msg = codec.decode_state(state.payload.to_bytes())
                self._last_state = (list(msg.pose), msg.q)
                self.read["state"] += 1
            if target is not None:
                self._last_target = codec.decode_target(target.payload.to_bytes())
                self.read["target"] += 1
        except Exception:
            self.dropped += 1
        snap.pose, snap.q = self._last_state
        snap.target = self._last_target
        with self._lock:
            snap.objects = dict(self._objects)
            snap.inputs = dict(self._inputs)
            snap.status, snap.scene = self._status, self._scene
        return snap

    def counts(self) -> tuple[dict[str, int], int]:
        """Messages read by key, and those that did not decode."""
        with self._lock:
            return dict(sorted(self.read.items())), self.dropped

    def close(self) -> None:
        for s in (self._state, self._target, *self._subs):
            s.undeclare()

    def __enter__(self) -> Feed:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_view(session: zenoh.Session, keys: Keys, view: LiveView, stop: threading.Event,
             rate: float = RATE) -> dict:
    """Draw the robot's keys on ``view`` at ``rate`` until ``stop`` is set; what it did:
    ``{frames, read: {key: messages}, dropped, skills: [ids drawn], fetch_failures}``
    (the 1 kHz keys count the messages drawn from, one a frame at most). The active
    bundle is fetched beside the drawing: a daemon slow to answer never stops the view."""
    task = view.task
    objects = set(task.scene.bodies) if task is not None else set()
    report: dict = {"frames": 0, "skills": [], "fetch_failures": 0}
    with Feed(session, keys, objects) as feed, BundleFetcher(session, keys) as fetcher:
        skill_id, retry = None, 0.0
        period, due = 1.0 / rate, time.monotonic()
        while not stop.is_set():
            snap = feed.snapshot()
            wanted = (snap.status or {}).get("skill")
            if wanted and wanted != skill_id and snap.t >= retry:
                fetcher.want(str(wanted))
            done = fetcher.take()
            if done is not None:
                skill, got = done
                if skill is not None:
                    view.set_skill(skill)
                    report["skills"].append(got)
                    skill_id, retry = got, 0.0
                else:
                    report["fetch_failures"] += 1
                    retry = time.monotonic() + FETCH_RETRY
            view.draw(snap)
            report["frames"] += 1
            due += period
            stop.wait(max(0.0, due - time.monotonic()))
        report["read"], report["dropped"] = feed.counts()
    return report


class BundleFetcher:
    """Fetches the active bundle on a thread of its own, one fetch at a time (a context
    manager: waits for the fetch in flight at exit)."""

    def __init__(self, session: zenoh.Session, keys: Keys):
        self.session, self.keys = session, keys
        self._thread: threading.Thread | None = None
        self._done: tuple | None = None

    def want(self, skill_id: str) -> None:
        """Start fetching unless a fetch is in flight or waits to be taken."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._fetch, args=(skill_id,), name="sctd-view-fetch",
                                            daemon=True)
            self._thread.start()

    def take(self) -> tuple | None:
        """A finished fetch: (skill, its id), or (None, None) when it failed; None while
        none has finished."""
        if self._thread is None or self._thread.is_alive():
            return None
        self._thread, done, self._done = None, self._done, None
        return done

    def _fetch(self, wanted: str) -> None:
        from sctd.skill import SkillError, skill_from_bundle

        got = client.active_bundle(self.session, self.keys, timeout=5.0, find=2.0)
        if isinstance(got, str):
            log.warning("cannot fetch the active skill %s: %s", wanted, got)
            self._done = (None, None)
            return
        bundle, meta = got
        try:
            skill = skill_from_bundle(bundle)
        except SkillError as e:  # a bundle the daemon runs loads; if not, say so
            log.warning("cannot load the active skill %s: %s", wanted, e)
            self._done = (None, None)
            return
        log.info("drawing skill %s@%s", meta.get("name"), meta.get("id"))
        self._done = (skill, str(meta.get("id")))

    def __enter__(self) -> BundleFetcher:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._thread is not None:
            self._thread.join(10.0)
