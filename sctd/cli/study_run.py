"""``sctd study run --participant ID``: the runner for people (``docs/study.md``,
"Running a study with people").

What ``sctd try`` starts (:class:`~.tryout.Trials`: per trial the arm, the daemon, the
logger and the view on this command's loopback Zenoh port, the page an input device
through :class:`~sctd_services.input.page.PageGate`), with the study's pages on
127.0.0.1: the participant's (``/``), led by :class:`~sctd_services.study.runner.
StudyRunner` through the plan, and the experimenter's (``/experimenter``), which watches
and holds the pause and the safety stop. The study folder is locked against a second
runner (:class:`~sctd_services.study.lock.RunnerLock`); every result goes through the
store's writer API before the page hears of it.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from pathlib import Path
from typing import Any

from sctd.task import Task
from sctd_services.study.errors import StudyError
from sctd_services.study.plan import Plan, Step

from ..app.errors import EXIT_OK
from ..wire import Keys
from .procs import free_port
from .tryout import STOPPED, Trials, _plain, page_endpoint

PAGES = {"/": ("sctd_services.study", "participant.html"),
         "/experimenter": ("sctd_services.study", "experimenter.html"),
         "/input.js": ("sctd_services.tryout", "input.js"),
         "/input.css": ("sctd_services.tryout", "input.css")}
REQUESTS = ("start", "abort", "next", "answers")  # the participant page's
PAGE_CLOSED = "the participant's page closed"
WATCH = 0.25  # s between the main thread's looks at the participant's page


class StudySession:
    """One participant's session: the runner, the trials' rig and the pages' requests
    (every call on the runner under one lock: the pages' thread, the trial's thread and
    the main thread all reach it)."""

    def __init__(self, runner: Any, trials: Trials, tasks: dict[str, Task]):
        self.runner, self.trials, self.tasks = runner, trials, tasks
        self.lock = threading.Lock()
        self._blocks: dict[tuple[str, str], Any] = {}

    def state(self) -> dict[str, Any]:
        with self.lock:
            screen = self.runner.screen()
        return {"study": screen, **self.trials.state()}

    def request(self, msg: dict) -> str | None:
        """The participant page's ``next``, ``start``, ``abort`` (their stop) and ``answers``."""
        kind = msg.get("type")
        with self.lock:
            if kind == "next":
                return self.runner.next()
            if kind == "answers":
                return self.runner.answer({k: msg.get(k) for k in ("nasa_tlx", "sus")})
            if kind == "abort":
                return self._abort("stopped by the participant")
            step = self.runner.start()
            if isinstance(step, str):
                return step
            try:
                return self._launch(step)
            except Exception as e:  # (a skill file gone since the plan was made): said, and comes again
                self.runner.abort(f"not started: {e}")
                return f"the trial could not start: {e}"

    def watch(self, msg: dict) -> str | None:
        """The experimenter page's ``pause``, ``unpause`` and ``safety_stop``."""
        kind = msg.get("type")
        with self.lock:
            if kind == "pause":
                self.runner.pause()
                if self.runner.running is not None:
                    self._abort("paused by the experimenter")
                return None
            if kind == "unpause":
                self.runner.unpause()
                return None
            if kind == "safety_stop":
                return self._abort("safety stop by the experimenter")
        return f"no such request: {kind!r}"

    def _abort(self, reason: str) -> str | None:
        if self.runner.running is None:
            return "no trial is running"
        self.trials.abort(reason)
        return None

    def _launch(self, step: Step) -> str | None:
        from sctd.skill import bundle_from_skill
        from sctd_services.eval.evaluate import write_bundle
        from sctd_services.study.conditions import block_of
        from sctd_services.study.runner import rig_folder

        key = (step.condition, step.task)
        if key not in self._blocks:
            self._blocks[key] = block_of(self.runner.store.plan, step.condition, self.tasks[step.task])
        block = self._blocks[key]
        attempt = self.runner.attempt(step)
        folder = rig_folder(self.runner.folder, step, attempt)
        path = write_bundle(bundle_from_skill(block.skill), folder / "skill")
        skill = {"skill": block.label, "name": block.skill.name, "id": block.skill.id,
                 "condition": step.condition, "path": str(path)}

        def done(entry: dict[str, Any] | None, error: str | None) -> None:
            self._ended(step, attempt, folder, entry, error)

        # the last trial's thread is past its done (its row is written) but may still be
        # ending: wait for it rather than refuse the participant's start
        self.trials.join(10.0)
        why = self.trials.launch(block.task, skill, step.seed, folder, done)
        if why is not None:
            self.runner.abort(f"not started: {why}")
        return why

    def _ended(self, step: Step, attempt: int, folder: Path, entry: dict[str, Any] | None,
               error: str | None) -> None:
        """A trial's end (the trial's thread): recorded as finished or as aborted."""
        pid = self.runner.participant
        if entry is not None:
            entry = {k: v for k, v in _plain(entry).items() if k != "path"}  # (no absolute paths)
            entry["mcap"] = str(Path(entry["mcap"]).relative_to(self.runner.folder))
            (folder / "trial.json").write_text(json.dumps(entry, indent=1) + "\n")
        with self.lock:
            reason = _aborted(entry, error, self.trials.abort_reason, self.trials.stop.is_set())
            if reason is not None:
                self.runner.abort(reason, None if entry is None else entry.get("duration_s"))
                print(f"sctd study run: {pid} step {step.index}: aborted ({reason})", file=sys.stderr,
                      flush=True)
                return
            assert entry is not None
            log = {"participant": pid, "step": step.index, "attempt": attempt, "condition": step.condition,
                   "task": step.task, "seed": step.seed, "practice": step.practice, "device": "browser",
                   "result": entry}
            self.runner.finish(entry, log)
        print(f"sctd study run: {pid} step {step.index}: {entry['outcome']}, {entry['reason']}",
              file=sys.stderr, flush=True)

    def check_page(self) -> None:
        """A running trial whose participant page has gone (closed, reloaded, its
        connection lost) is aborted."""
        with self.lock:
            if self.runner.running is not None and self.trials.gate.controller is None \
                    and self.trials.abort_reason is None:
                self.trials.abort(PAGE_CLOSED)


def _aborted(entry: dict[str, Any] | None, error: str | None, asked: str | None, stopped: bool) -> str | None:
    """Why a trial that ended so counts as aborted (``asked``: the abort's reason, if one
    was asked for; ``stopped``: the command is ending); None when it ended by its outcome."""
    reason = None if entry is None else entry.get("reason")
    if asked is not None and (entry is None or reason == asked):
        return asked
    if stopped and (entry is None or reason == STOPPED):
        return "the runner was stopped during the trial"
    if entry is None:
        return f"the trial's programs failed: {error}"
    return None


def check_participant(plan: Plan, pid: str) -> None:
    """``pid`` is a pseudonym of ``plan``, and the plan's conditions are ones the runner
    runs; a :class:`StudyError` naming the flag otherwise."""
    from sctd_services.study.questionnaires import check_participant_id

    try:
        check_participant_id(pid)
        plan.schedule(pid)
    except StudyError as e:
        raise StudyError(f"--participant: {e}") from None
    sets = [c.name for c in plan.conditions if c.kind == "set"]
    if sets:
        raise StudyError(f"--plan: condition {sets[0]}: a skill set's blocks are not run with people yet "
                         "(docs/study.md); skills and teleop are")


def main_run_people(args: argparse.Namespace, plan: Plan, tasks: dict[str, Task]) -> int:
    """The runner for ``args.participant`` (checked by :func:`check_participant` first)."""
    from sctd_services.study.lock import RunnerLock
    from sctd_services.study.runner import StudyRunner
    from sctd_services.study.store import StudyStore

    pid = args.participant
    try:
        endpoint = page_endpoint(args)  # before anything is made or locked
    except ValueError as e:
        raise StudyError(str(e)) from None
    store = StudyStore.create(args.out, plan)
    with RunnerLock(args.out) as lock:
        if lock.stale is not None:
            print(f"sctd study run: {lock.path}: took over the lock of pid {lock.stale}, which is not "
                  "running (a runner killed or crashed)", file=sys.stderr, flush=True)
        runner = StudyRunner(store, pid, {name: t.title for name, t in tasks.items()})
        if runner.recovered:
            print(f"sctd study run: {runner.recovered}", file=sys.stderr, flush=True)
        return _serve(args, runner, tasks, endpoint)


def _serve(args: argparse.Namespace, runner: Any, tasks: dict[str, Task], endpoint: tuple[str, Any]) -> int:
    from sctd.wire.session import MSGPACK, session
    from sctd_services.input.page import DEVICE, PageGate
    from sctd_services.tryout.server import PageServer

    host, tls = endpoint
    hub = f"tcp/127.0.0.1:{free_port()}"
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    hello = {"title": runner.store.plan.title, "participant": runner.participant}
    try:
        with session(listen=[hub]) as s, \
                s.declare_publisher(Keys().input(DEVICE), express=True, encoding=MSGPACK) as pub:
            gate = PageGate(pub.put)
            with Trials(s, hub, gate, runner.folder / "logs", 0, not args.no_view, []) as trials:
                study = StudySession(runner, trials, tasks)
                try:
                    server = PageServer(gate, study.request, study.state, hello, args.port, pages=PAGES,
                                        requests=REQUESTS, on_watch=study.watch, host=host, tls=tls)
                except OSError as e:
                    raise StudyError(f"--port: {e}") from None
                with server:
                    url = server.url
                    print(f"sctd study run: {runner.participant}: open {url} (the participant's page); the "
                          f"experimenter's: {url}experimenter (Zenoh {hub}); recording in {runner.folder}",
                          file=sys.stderr, flush=True)
                    try:
                        while not stop.wait(WATCH):
                            study.check_page()
                    except KeyboardInterrupt:
                        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
    p = runner.store.progress(runner.participant)
    print(f"sctd study run: {runner.participant}: stopped; {p.done}/{p.total} trials recorded"
          f"{', all questionnaires' if p.finished else ''}", file=sys.stderr, flush=True)
    return EXIT_OK
