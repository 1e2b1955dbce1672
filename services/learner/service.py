"""``sctd learner``: stores demonstrations, trains on request, checks, hot-swaps.

Zenoh (docs/wire-contract.md, docs/learner.md):

- subscribes ``sctd/<robot>/demos/**``: every demonstration is decoded and validated on
  arrival (:func:`sctd.wire.codec.decode_demo`) and stored by task; a malformed one
  is refused with its name, row and reason on ``sctd/<robot>/learner/status``, nothing
  stored;
- answers ``sctd/<robot>/learner`` (the request: :mod:`.request`): trains with
  :mod:`sctd.learn`, stores the skill by content id, checks it with lockstep trials
  (:mod:`.check`) and, when it passes, swaps it into the daemon through its ``skill``
  queryable (into a running skill set, in place of the member :mod:`.member` chooses);
  one reply after all that, ``{id, name, ref, swapped, member, reason, summary, report,
  evaluation, timings}``, or an error reply ``{error}``;
- publishes on ``sctd/<robot>/learner/status`` what it stored or refused, each stage of
  a training as it ends, each trial of a check, and once a second its state.

Requests are served one at a time, in order, on the service's own thread; the
daemon never waits for the learner (a swap is one query the daemon answers between
two ticks), so a learner killed at any moment leaves the daemon running its skill.
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
import threading
import time
from collections import Counter
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from sctd.learn import DemoError, skill_bundle
from sctd.learn.summary import plain, summary_dict
from sctd.skill import SkillError, bundle_from_file, skill_from_bundle, skill_summary
from sctd.skill.catalog import StoredSkill, store_folder
from sctd.wire import DEFAULT_ROBOT, Keys, client, codec
from sctd.wire.session import MSGPACK

from .check import CheckSettings, evaluable, evaluation, verdict
from .member import NoMember, member_to_replace, replaced_skill_id
from .request import Request, RequestError, parse_request, request_map
from .store import SkillRecord, Store, StoreFull
from .training import Trainer, TrainingError

log = logging.getLogger("sctd.learner")


class Stopped(BaseException):
    """Raised in the service's thread by SIGINT/SIGTERM while a request is served: the
    request gets an error reply and the learner exits (a signal while idle just ends
    the loop)."""

STATUS_PERIOD = 1.0  # s between the learner's state messages
DAEMON_TIMEOUT = 3.0  # s to wait for the daemon's skill summary
SWAP_TIMEOUT = 40.0  # s to wait for a swap's reply (the daemon validates within 30 s)
PER_SAMPLE = ("labels", "field_labels", "graph_labels")  # report keys with a label per sample


def _jsonable(obj: Any) -> Any:
    """Plain lists, maps, numbers and strings (numpy values converted)."""
    return json.loads(json.dumps(obj, default=plain))


@dataclass
class _Outcome:
    """A request's result as it is replied."""

    stored: StoredSkill
    passed: bool | None  # the check passed; None: not checked (gate: false, allowed by the operator)
    swapped: bool
    reason: str
    summary: dict[str, Any]
    report: dict[str, Any]
    evaluation: dict[str, Any] | None
    timings: dict[str, float]
    daemon: dict[str, Any] | None

    @property
    def member(self) -> str | None:
        """The member of the daemon's skill set the skill replaced (None: not swapped, or
        no set)."""
        return self.daemon.get("member") if self.swapped and self.daemon else None

    def reply(self) -> dict[str, Any]:
        """The reply map; the report without its per-sample labels (the record on disk
        keeps them)."""
        s = self.stored
        report = {k: v for k, v in self.report.items() if k not in PER_SAMPLE}
        return {"id": s.id, "name": s.name, "ref": s.ref, "passed": self.passed,
                "checked": self.passed is not None, "swapped": self.swapped, "member": self.member,
                "reason": self.reason, "summary": self.summary, "report": report,
                "evaluation": self.evaluation, "timings": self.timings, "daemon": self.daemon,
                "path": str(s.path)}


class Learner:
    """The learner service's declarations and request loop.

    A context manager: subscribed and answering while entered; :meth:`serve` runs the
    request loop until its ``stop`` event is set.

    Parameters
    ----------
    session : zenoh.Session
    store : Store
    robot : str
    settings : CheckSettings
    pool : Executor, optional
        Where the check's trials run (default: in this process, one after the other).
    """

    def __init__(self, session: zenoh.Session, store: Store, robot: str = DEFAULT_ROBOT,
                 settings: CheckSettings | None = None, pool: Executor | None = None,
                 trainer: Trainer | None = None) -> None:
        self.session = session
        self.store = store
        self.keys = Keys(robot)
        self.settings = settings or CheckSettings()
        self.pool = pool
        self.trainer = trainer or Trainer()
        self.counters: Counter[str] = Counter()
        self.busy: dict[str, Any] | None = None
        self.stage = "idle"  # what the service's thread is doing, for status and errors
        self._stack = contextlib.ExitStack()
        self._lock = threading.Lock()

    def __enter__(self) -> Learner:
        with contextlib.ExitStack() as stack:
            s = self.session
            self._status = stack.enter_context(
                s.declare_publisher(self.keys.learner_status, encoding=MSGPACK))
            stack.enter_context(s.declare_subscriber(f"{self.keys.prefix}/demos/**", self._on_demo))
            self.queries = stack.enter_context(
                s.declare_queryable(self.keys.learner, zenoh.handlers.FifoChannel(64)))
            quit_beat = threading.Event()
            beat = threading.Thread(target=self._heartbeat, args=(quit_beat,), name="learner-status",
                                    daemon=True)
            beat.start()
            stack.callback(beat.join)
            stack.callback(quit_beat.set)
            self._stack = stack.pop_all()
        return self

    def _heartbeat(self, quit: threading.Event) -> None:
        """The learner's state once a second: ready or busy (with what), the store."""
        while not quit.is_set():
            try:
                self.say("state", state="busy" if self.busy else "ready", doing=self.stage,
                         store=str(self.store.root), tasks=self.store.tasks(),
                         skills=len(self.store.skills()), counters=dict(self.counters))
            except Exception:  # a store being written or a closing session: next second
                log.debug("status failed", exc_info=True)
            quit.wait(STATUS_PERIOD)

    def __exit__(self, *exc: object) -> None:
        self._stack.close()
        self.trainer.close()

    def say(self, event: str, **fields: Any) -> None:
        """One status message ``{event, stamp, ...}`` on ``learner/status``."""
        msg = {"event": event, "stamp": time.time(), **fields}
        with self._lock:
            self._status.put(codec.pack(_jsonable(msg)))

    # --- demonstrations (Zenoh's threads) ---------------------------------------------

    def _on_demo(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        name = key.rsplit("/", 1)[-1]
        try:
            msg = codec.decode_demo(sample.payload.to_bytes())
            if key != self.keys.demos(msg.task, msg.name):
                raise codec.DecodeError("key_mismatch", f"the message is {msg.task}/{msg.name}")
            stored = self.store.add_demo(msg, key)
        except codec.DecodeError as e:
            self.counters["rejected"] += 1
            row = re.search(r"\brow (\d+)", str(e))
            self.say("rejected", key=key, name=name, reason=e.reason, detail=str(e),
                     row=int(row.group(1)) if row else None)
            log.warning("refused demonstration %s: %s", key, e)
            return
        except StoreFull as e:
            self.counters["rejected"] += 1
            self.say("rejected", key=key, name=name, reason=e.reason, detail=str(e), row=None)
            log.warning("refused demonstration %s: %s", key, e)
            return
        except OSError as e:
            self.counters["store_failed"] += 1
            self.say("rejected", key=key, name=name, reason="store", detail=str(e), row=None)
            return
        self.counters["duplicates" if stored.duplicate else "stored"] += 1
        self.say("duplicate" if stored.duplicate else "stored", key=key, task=stored.task,
                 name=stored.name, object=stored.object, rows=len(msg.rows), path=str(stored.path))
        log.info("%s demonstration %s/%s (%d rows)", "already had" if stored.duplicate else "stored",
                 stored.task, stored.name, len(msg.rows))

    # --- requests (the service's thread) ----------------------------------------------

    def serve(self, stop: threading.Event) -> None:
        """Answer requests in order until ``stop``."""
        while not stop.is_set():
            query = self.queries.try_recv()
            if query is None:
                stop.wait(0.02)
                continue
            with query:
                self.answer(query)

    def answer(self, query: zenoh.Query) -> None:
        """Serve one request; every request gets one reply (an error reply ``{error}``
        when it cannot be served)."""
        payload = query.payload
        try:
            req = parse_request(b"" if payload is None else payload.to_bytes())
            out = self.handle(req)
        except (RequestError, DemoError, SkillError, TrainingError, KeyError, TypeError, ValueError) as e:
            self._refuse(query, str(e).strip("'\""))
            return
        except Exception as e:  # every request gets a reply, whatever went wrong
            log.exception("training request failed")
            self._refuse(query, f"{type(e).__name__}: {e}")
            return
        except Stopped:
            self._refuse(query, f"the learner was stopped while {self.stage}")
            raise
        query.reply(self.keys.learner, codec.pack(_jsonable(out.reply())), encoding=MSGPACK)

    def _refuse(self, query: zenoh.Query, error: str) -> None:
        self.counters["requests_refused"] += 1
        self.say("error", error=error)
        log.warning("refused request: %s", error)
        query.reply_err(codec.pack({"error": error}), encoding=MSGPACK)

    def handle(self, req: Request) -> _Outcome:
        """Train, store, check and swap (see the module docstring); raises on a request
        that cannot be served (unknown demonstrations, a skill that does not load)."""
        if not req.gate and not self.settings.allow_unchecked:
            raise RequestError("gate", "false: this learner checks every skill before a swap (its "
                                       "operator can start it with --allow-unchecked)")
        t0 = time.monotonic()
        self.busy = {"task": req.task, "method": req.method, "since": time.time()}
        try:
            self.stage = f"training {req.task} ({req.method})"
            stored, skill, report = self._train(req)
            record = self.store.record(stored.id)
            t1 = time.monotonic()
            self.stage = f"checking {stored.ref}"
            ev, passed, reason = self._check(req, stored, record)
            t2 = time.monotonic()
            self.stage = f"swapping {stored.ref} in"
            swapped, reason, daemon = self._swap(stored, req, passed, reason, record)
        finally:
            self.busy = None
            self.stage = "idle"
        t3 = time.monotonic()
        timings = {"train_s": round(t1 - t0, 3), "check_s": round(t2 - t1, 3),
                   "swap_s": round(t3 - t2, 3), "total_s": round(t3 - t0, 3)}
        record.update({"timings": timings})
        record.save()
        self.counters["swapped" if swapped else "kept"] += 1
        out = _Outcome(stored, passed, swapped, reason, skill_summary(skill), report, ev, timings, daemon)
        self.say("swapped" if swapped else "kept", id=stored.id, name=stored.name, member=out.member,
                 reason=reason, timings=timings)
        return out

    def _train(self, req: Request) -> tuple[StoredSkill, Any, dict[str, Any]]:
        demos = self.store.load_demos(req.task, req.demos)
        names = [d.name.rsplit(".", 1)[0] for d in demos]
        obj = req.object or self._object_of(req.task, names)
        self.say("training", task=req.task, method=req.method, demos=len(demos), stage="start")
        doing = self.stage

        def on_stage(stage: str) -> None:
            self.stage = f"{doing}, after {stage}"
            self.say("training", task=req.task, stage=stage)

        # in a child process: capped memory and time, a lower priority (.training)
        result = self.trainer.train(demos, req.method, req.frames or None, {"object": obj, **req.params},
                                    on_stage)
        bundle = skill_bundle(result, req.skill_name)
        skill = skill_from_bundle(bundle)  # a learned skill the runtime would refuse is an error
        report = _jsonable(summary_dict(result, skill, str(self.store.demos_dir / req.task),
                                        settings=req.params))
        stored = self.store.add_skill(bundle, {
            "task": req.task, "method": req.method, "object": obj, "demos": names,
            "hyperparameters": report["hyperparameters"], "request": request_map(req),
            "report": report, "evaluation": {}})
        self.say("trained", id=stored.id, name=stored.name, path=str(stored.path))
        return stored, skill, report

    def _object_of(self, task: str, names: list[str]) -> str:
        objects = {self.store.demo_object(task, n) for n in names}
        if len(objects) != 1 or None in objects:
            raise RequestError("object", f"the demonstrations of {task!r} are in the frames of "
                                         f"{sorted(map(str, objects))}: name the object")
        return str(objects.pop())

    def _check(self, req: Request, stored: StoredSkill, record: SkillRecord
               ) -> tuple[dict[str, Any] | None, bool | None, str]:
        """The lockstep check (with the gate on): its evaluation, whether it passed (None:
        not checked), why; the evaluation and the verdict go into ``record`` (not yet
        written)."""
        if not req.gate:
            reason = "not checked (gate: false, allowed by the learner's operator)"
            record.update({"check": {"passed": None, "checked": False, "reason": reason}})
            return None, None, reason
        task = evaluable(req.task)
        if task is None:
            return None, *verdict(None, req.task, self.settings, None)
        seed = self.settings.seed if req.seed is None else req.seed
        active = self._active_evaluation(req, stored, record.data.get("object"))
        ev = evaluation(stored, task, self.settings, seed, self.pool,
                        lambda k, n, _label: self.say("checking", id=stored.id, trial=k, of=n),
                        active=active)
        passed, reason = verdict(ev, req.task, self.settings, active)
        record.update({"evaluation": {**record.data.get("evaluation", {}), req.task: ev},
                       "check": {"passed": passed, "reason": reason, "evaluation": ev}})
        return ev, passed, reason

    def _active_evaluation(self, req: Request, stored: StoredSkill, obj: str | None
                           ) -> dict[str, Any] | None:
        """The stored evaluation on the request's task of the skill ``stored`` would
        replace: the running skill's, or with a skill set the replaced member's
        (:func:`.member.replaced_skill_id`; a set runs teleoperation until a member
        engages). None: no daemon, no member chosen, not from the store, the same skill,
        or never evaluated on the task."""
        sid = replaced_skill_id(self.daemon_summary(), req.member, stored.name, obj)
        if not sid or sid == stored.id:
            return None
        s = self.store.skill(sid)
        return None if s is None else s.record.get("evaluation", {}).get(req.task)

    def daemon_summary(self) -> dict[str, Any] | None:
        """The daemon's active skill summary, or None when no daemon answers."""
        return client.active_skill(self.session, self.keys, DAEMON_TIMEOUT, find=1.0)

    def _swap(self, stored: StoredSkill, req: Request, passed: bool | None, reason: str,
              record: SkillRecord) -> tuple[bool, str, dict[str, Any] | None]:
        """Swap the skill into the daemon when it passed (or was not checked) and the
        request asks for it; into a running skill set in place of the member
        :func:`.member.member_to_replace` chooses, or not at all when it chooses none. A
        swap goes into ``record``. The record is written before the daemon is asked: from
        then on the daemon may run the skill, and a learner that dies before the reply
        must leave its check (the baseline of later checks, what ``sctd skills`` shows)
        on disk."""
        if passed is False:
            return False, f"kept the active skill: {reason}", None
        if not req.swap:
            return False, f"stored, not swapped (swap: false); check: {reason}", None
        try:  # the summary of now, not the check's: the set may have changed meanwhile
            member = member_to_replace(self.daemon_summary(), req.member, stored.name,
                                       record.data.get("object"))
        except NoMember as e:
            return False, f"stored, not swapped: {e}; check: {reason}", None
        record.save()
        self.say("swapping", id=stored.id, member=member)
        # the member of the skill's own name, found by name, is the daemon's default: not
        # named, so that a name a selector cannot carry (client.MEMBER_NAME_RULE) is replaced too
        named = None if req.member is None and member == stored.name else member
        ok, body = client.swap(self.session, self.keys, bundle_from_file(stored.path), SWAP_TIMEOUT,
                               member=named)
        if ok:
            replaced = body.get("member")
            record.update({"swaps": [*record.data.get("swaps", []), time.time()], "member": replaced})
            return True, (f"swapped: {reason}" if replaced is None else
                          f"swapped, replacing the member {replaced!r}: {reason}"), body
        return False, f"not swapped: {body.get('error', body)}; check: {reason}", body


def store_path(folder: str | Path | None) -> Path:
    """The store's folder: given, or the default (:func:`sctd.skill.catalog.store_folder`)."""
    return Path(folder) if folder else store_folder()
