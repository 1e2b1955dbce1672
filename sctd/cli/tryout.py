"""``sctd try``: drive sctd from a browser page, to feel what a skill does (``docs/try.md``).

One command on one machine: a page on 127.0.0.1 (:mod:`sctd_services.tryout.server`)
where a person picks a task and a skill for it, or teleoperation (the competent baseline
of ``sctd eval``: the shipped teleop with the skill's limits and the task's control
frame), starts a trial and drives the arm with a gamepad, the keyboard or an on-screen
stick. The page is an input device like any other (:mod:`sctd_services.input.page`: the
arbiter sees ``input/browser``, with a deadman, stale when the page hides).

Per trial, as a real-time trial of ``sctd eval`` (:mod:`.eval_realtime`), on this
command's loopback Zenoh port: ``sctd sim --trial-seed N``, ``sctd run`` with the
skill, ``sctd log --mcap`` and ``sctd view`` (the page shows it in a frame), watched by
the same :class:`~sctd_services.eval.trial.TrialRecorder`, which judges the task's
outcome. Each trial gets a folder under ``--out`` with ``trial.json`` (the fields of
``sctd eval --json``'s per-trial entries) and ``trial.mcap``. The arm and the view stay
up after a trial until the next one starts; Ctrl-C or SIGTERM stops everything.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from ..app.errors import EXIT_OK, fail
from ..wire import Keys, codec
from .procs import Child, free_port

Done = Callable[[dict[str, Any] | None, str | None], None]  # a trial's end: its entry, or why it failed
STARTUP = 90.0  # s for the arm and the daemon to publish, on a loaded machine
STUCK_AFTER = 10.0  # s without progress: the trial is stuck (as sctd eval's default)
STOPPED = "sctd try stopped"  # the reason of a trial the command's end cut short


def add_try_arguments(p: argparse.ArgumentParser) -> None:
    p.description = ("Drive sctd from a browser: a page on 127.0.0.1 where you pick a task and a skill (or "
                     "teleoperation), start a trial and drive the simulated arm with a gamepad, the keyboard "
                     "or an on-screen stick; each trial is judged and recorded (docs/try.md).")
    p.add_argument("--port", type=int, default=0, help="the page's port on 127.0.0.1 (default 0: a free one; "
                                                        "the URL goes to stderr)")
    p.add_argument("--out", metavar="DIR",
                   help="where the trials are recorded, a folder each (default: a new folder sctd-try-* in "
                        "the temporary folder)")
    p.add_argument("--seed", type=int, default=0, help="the first trial's start (sctd sim --trial-seed); "
                                                       "the next trials take the next seeds (default 0)")
    p.add_argument("--no-view", action="store_true",
                   help="without the live 3D view in the page (a machine without a GPU to spare)")
    add_page_arguments(p)


def add_page_arguments(p: argparse.ArgumentParser) -> None:
    """``--page-host`` and ``--page-tls``: where a page is served, and with what (sctd try,
    sctd study run)."""
    p.add_argument("--page-host", default="127.0.0.1", metavar="ADDR",
                   help="the address the page listens on (default %(default)s); off this machine's loopback "
                        "it needs --page-tls")
    p.add_argument("--page-tls", metavar="DIR",
                   help="serve HTTPS and WSS with the certificates of sctd certs in DIR (sctd-router.pem and "
                        "its key, ca.pem): every browser presents a client certificate of that CA, and its "
                        "role decides what it may do (sctd-input drives, sctd-observer watches: docs/try.md)")


def page_endpoint(args: argparse.Namespace) -> tuple[str, Any]:
    """The page's address and TLS context (None: plain HTTP) from ``--page-host`` and
    ``--page-tls``; ValueError naming the flag when a non-loopback address comes without
    TLS, or the TLS folder cannot serve."""
    from sctd_services.tryout.server import PageTLSError, page_tls

    from ..wire.session import is_loopback

    if args.page_tls is None:
        if not is_loopback(args.page_host):
            raise ValueError(f"--page-host {args.page_host}: serving the page off this machine needs "
                             "--page-tls DIR (mutual TLS, the certificates of sctd certs: docs/deploy.md)")
        return args.page_host, None
    try:
        return args.page_host, page_tls(args.page_tls)
    except PageTLSError as e:
        raise ValueError(f"--page-tls: {e}") from None


def catalog() -> list[dict[str, Any]]:
    """The tasks (``sctd tasks``) with the skills whose object is theirs (``sctd
    skills``: stored, newest first, then shipped)."""
    from ..skill import SkillError, load_skill
    from ..skill.catalog import shipped_skills, stored_skills
    from ..task import TaskError, known_tasks, load_task

    skills: list[tuple[str, str]] = []
    for name, path in [*((s.name, s.path) for s in reversed(stored_skills())),
                       *((p.stem, p) for p in shipped_skills())]:
        try:
            skills.append((name, load_skill(path).object))
        except SkillError:
            continue
    tasks = []
    for k in known_tasks():
        try:
            t = load_task(k.path)
        except TaskError:
            continue
        names = list(dict.fromkeys(n for n, obj in skills if obj == t.object))
        tasks.append({"name": k.name, "title": t.title, "object": t.object, "skills": names})
    return tasks


def _plain(x: Any) -> Any:
    """``x`` with non-finite floats as None (JSON a browser parses)."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_plain(v) for v in x]
    return x


class Trials:
    """The trials of one ``sctd try``: started on the page's request, one at a time, each
    on a rig of processes connected to ``hub`` (a context manager: stops them)."""

    def __init__(self, session: Any, hub: str, gate: Any, out: Path, seed: int, view: bool,
                 tasks: list[dict[str, Any]]):
        self.session, self.hub, self.gate, self.out = session, hub, gate, out
        self.seed, self.view, self.tasks = seed, view, {t["name"]: t for t in tasks}
        self.n = 0
        self.lock = threading.Lock()
        self.trial: dict[str, Any] = {"phase": "idle"}
        self.result: dict[str, Any] | None = None
        self.status: dict[str, Any] = {}
        self.view_url: str | None = None
        self._view_port: int | None = None
        self.stop = threading.Event()
        self._abort = threading.Event()
        self.abort_reason: str | None = None
        self._rig = ExitStack()
        self._thread: threading.Thread | None = None
        self._sub = session.declare_subscriber(Keys().status, self._on_status)

    def __enter__(self) -> Trials:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        if self._thread is not None:
            self._thread.join(30.0)
        self._sub.undeclare()
        self._rig.close()
        self.gate.set_open(False)

    def _on_status(self, sample: Any) -> None:
        try:
            msg = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        inp, counters = msg.get("input"), msg.get("counters")
        inp = inp if isinstance(inp, dict) else {}
        counters = counters if isinstance(counters, dict) else {}
        rearm = inp.get("rearm")
        self.status = {"state": msg.get("state"), "mode": msg.get("mode"), "skill": msg.get("skill_name"),
                       # what the mode button does in that state: the state it enters, or None
                       "mode_button": msg.get("mode_button"),
                       "owner": inp.get("owner"), "input_age": msg.get("input_age"),
                       # why the page's stick must be centred before the arm moves again, or None
                       "rearm": rearm.get("browser") if isinstance(rearm, dict) else None,
                       "counters": {k: counters.get(k) for k in ("stale_input", "disabled_input",
                                                                 "nonfinite_input", "ignored_input")}}

    def state(self) -> dict[str, Any]:
        """What every page is told, besides its role and the gate's counters."""
        with self.lock:
            return _plain({"trial": dict(self.trial), "result": self.result, "status": self.status,
                           "out": str(self.out), "view_url": self.view_url})

    def abort(self, reason: str = "aborted on the page") -> None:
        """End the running trial (a failure for ``sctd try``; the study's runner records it
        as aborted, ``reason`` saying why)."""
        self.abort_reason = reason
        self._abort.set()

    def request(self, msg: dict) -> str | None:
        """A controller's ``start`` or ``abort``; why it is refused, or None."""
        if msg.get("type") == "abort":
            self.abort()
            return None
        task, condition = msg.get("task"), msg.get("condition")
        if task not in self.tasks:
            return f"no task {task!r}"
        if condition != "teleop" and condition not in self.tasks[task]["skills"]:
            return f"no skill {condition!r} for the task {task}"
        if condition == "teleop" and not self.tasks[task]["skills"]:
            return f"the task {task} has no skill whose limits the baseline would take"
        with self.lock:
            seed = self.seed + self.n
            why = self._spawn(self._trial, str(task), str(condition), seed)
            self.n += why is None
        return why

    def launch(self, task: Any, skill: dict[str, Any], seed: int, folder: Path, done: Done) -> str | None:
        """Run a trial of ``skill`` (as :func:`_skill_for` describes one) on ``task`` from
        ``seed``, recorded in ``folder``, in a thread of its own; ``done(entry, error)``
        when it ends (``entry`` None when the rig failed, ``error`` saying why). Why it
        cannot start, or None."""
        with self.lock:
            return self._spawn(self._launched, task, skill, seed, folder, done)

    def join(self, timeout: float) -> None:
        """Wait for the last trial's thread to end (it records its result after its
        ``done``)."""
        if self._thread is not None:
            self._thread.join(timeout)

    def _spawn(self, target: Any, *args: Any) -> str | None:
        if self._thread is not None and self._thread.is_alive():
            return "a trial is running: abort it first"
        self._abort.clear()
        self.abort_reason = None
        self._thread = threading.Thread(target=target, args=args, name="sctd-try-trial", daemon=True)
        self._thread.start()
        return None

    def _set(self, **fields: Any) -> None:
        with self.lock:
            self.trial.update(fields)

    def _trial(self, task_name: str, condition: str, seed: int) -> None:
        from ..task import find_task

        folder = self.out / f"trial-{seed:03d}-{task_name}-{condition}"
        self._starting(task_name, condition, seed)
        try:
            task = find_task(task_name)
            skill = _skill_for(task, condition, folder)
        except Exception as e:  # said on the page and on stderr; the command goes on
            self._failed(seed, e)
            return
        self._launched(task, skill, seed, folder, self._tried)

    def _tried(self, entry: dict[str, Any] | None, error: str | None) -> None:
        if entry is None:
            return
        folder = Path(entry["mcap"]).parent
        (folder / "trial.json").write_text(json.dumps(_plain(entry), indent=1) + "\n")
        print(f"sctd try: trial {entry['seed']} ({entry['task']}, {entry['skill']}): {entry['outcome']}, "
              f"{entry['reason']}; {folder}", file=sys.stderr, flush=True)

    def _starting(self, task_name: str, label: str, seed: int) -> None:
        with self.lock:
            self.trial = {"phase": "starting", "task": task_name, "label": label, "seed": seed}
            self.result = None

    def _failed(self, seed: int, e: Exception) -> None:
        print(f"sctd try: trial {seed}: {e}", file=sys.stderr, flush=True)
        self._set(phase="error", error=str(e))
        self.gate.set_open(False)

    def _launched(self, task: Any, skill: dict[str, Any], seed: int, folder: Path, done: Done) -> None:
        """The trial of :meth:`launch`, in its thread."""
        self._starting(task.name, skill["skill"], seed)
        try:
            self._rig.close()  # the previous trial's arm, daemon and view
            self._rig, self.view_url, self._view_port = ExitStack(), None, None
            entry = self._run(task, skill, seed, folder)
        except Exception as e:  # said on the page and on stderr; the command goes on
            self._failed(seed, e)
            done(None, str(e))
            return
        done(entry, None)
        with self.lock:
            self.result = {k: entry[k] for k in ("outcome", "reason", "time_s", "duration_s")}
            self.result["folder"] = str(folder)
            self.trial["phase"] = "done"

    def _start_rig(self, task: Any, path: Path, seed: int, folder: Path) -> Child:
        """The arm, the daemon and the view (kept until the next trial); the log (its
        Child, stopped at the trial's end)."""
        def ep() -> str:
            return f"tcp/127.0.0.1:{free_port()}"

        rig, hub = self._rig, ["--connect", self.hub]
        rig.enter_context(Child("sctd.cli.main", "sim", "--task", task.name, "--trial-seed", str(seed), *hub,
                                "--listen", ep(), log=folder / "sim.log"))
        rig.enter_context(Child("sctd.cli.main", "run", "--skill", str(path), *hub, "--listen", ep(),
                                log=folder / "daemon.log"))
        if self.view:
            port = free_port()
            rig.enter_context(Child("sctd.cli.main", "view", "--task", task.name, "--view-port", str(port),
                                    *hub, log=folder / "view.log"))
            self._view_port = port
        return Child("sctd.cli.main", "log", "--mcap", str(folder / "trial.mcap"), *hub,
                     log=folder / "log.log")

    def _show_view(self) -> None:
        """Point the page at the view once it serves (its process takes a few seconds)."""
        from .procs import port_is_free

        port, end = self._view_port, time.monotonic() + 30.0
        while port is not None and port_is_free(port) and time.monotonic() < end and not self.stop.is_set():
            time.sleep(0.1)
        if port is not None:
            self.view_url = f"http://127.0.0.1:{port}/"

    def _run(self, task: Any, skill: dict[str, Any], seed: int, folder: Path) -> dict[str, Any]:
        """Start the rig, wait for it, then record the trial until its outcome, an abort or
        the command's end; the trial's JSON entry."""
        from sctd_services.eval.trial import TrialRecorder
        from sctd_services.eval.watcher import WATCH_RATE, TrialWatcher
        from sctd_services.user import PROFILES

        rec = TrialRecorder(task, seed, PROFILES["steady"].switch_time, None, STUCK_AFTER)
        w = TrialWatcher(self.session, task)
        first = last = None
        try:
            with self._start_rig(task, Path(skill["path"]), seed, folder):  # (the log)
                end = time.monotonic() + STARTUP
                while w.observation() is None:
                    if time.monotonic() > end or self.stop.is_set() or self._abort.is_set():
                        raise RuntimeError(f"the arm and the daemon did not start; see {folder}")
                    time.sleep(0.05)
                self._show_view()
                self.gate.set_open(True)
                self._set(phase="running")
                while not self.stop.wait(1.0 / WATCH_RATE):
                    obs = w.observation()
                    if self._abort.is_set() and first is None:  # aborted before it started
                        rec.end(self.abort_reason or "aborted on the page")
                        break
                    if obs is None or (first is None and not (w.buttons[1] and any(w.u))):
                        continue  # the trial starts with the person's first push
                    last = (time.monotonic(), obs.t)
                    first = first or last
                    self._set(elapsed=obs.t - (rec.t0 if rec.t0 is not None else obs.t))
                    if self._abort.is_set():
                        rec.end(self.abort_reason or "aborted on the page")
                    if rec.add(obs, w.u, w.buttons, w.status.get("vf_scale")) is not None:
                        break
                else:
                    rec.end(STOPPED)
                self.gate.set_open(False)
        finally:
            w.close()
        res = rec.result()
        if first is not None and last is not None and last[0] - first[0] > 1.0:
            res.sim_rtf = round((last[1] - first[1]) / (last[0] - first[0]), 3)
        return {**res.as_dict(), **skill, "task": task.name, "device": "browser",
                "mcap": str(folder / "trial.mcap"), "input": self.gate.report()["counts"]}


def _skill_for(task: Any, condition: str, folder: Path) -> dict[str, Any]:
    """The skill a trial runs: the named one, or for ``teleop`` the competent baseline of
    the task's first skill (written into ``folder``); its label, name, id, path and
    ``baseline_of``, as ``sctd eval --json`` names them."""
    from sctd.skill import bundle_from_file, load_skill
    from sctd.skill.catalog import find_skill
    from sctd_services.eval.evaluate import TELEOP, competent_baseline, write_bundle

    folder.mkdir(parents=True, exist_ok=True)
    if condition == "teleop":
        rows = [t for t in catalog() if t["name"] == task.name]
        ref = load_skill(find_skill(rows[0]["skills"][0]))
        bundle, label = competent_baseline(bundle_from_file(TELEOP), ref, task)
        path = write_bundle(bundle, folder / "teleop")
        baseline_of: str | None = ref.name
    else:
        path, label, baseline_of = find_skill(condition), condition, None
    skill = load_skill(path)
    return {"skill": label, "name": skill.name, "id": skill.id, "baseline_of": baseline_of,
            "condition": condition, "path": str(path)}


def main_try(args: argparse.Namespace) -> int:
    from sctd.wire.session import MSGPACK, session
    from sctd_services.input.page import DEVICE, PageGate
    from sctd_services.tryout.server import PageServer

    if not 0 <= args.port <= 65535:
        return fail("try", f"--port: not a TCP port: {args.port}")
    try:
        host, tls = page_endpoint(args)
    except ValueError as e:
        return fail("try", str(e))
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="sctd-try-"))
    out.mkdir(parents=True, exist_ok=True)
    hub = f"tcp/127.0.0.1:{free_port()}"
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    tasks = catalog()
    try:
        with session(listen=[hub]) as s, \
                s.declare_publisher(Keys().input(DEVICE), express=True, encoding=MSGPACK) as pub:
            gate = PageGate(pub.put)
            with Trials(s, hub, gate, out, args.seed, not args.no_view, tasks) as trials:
                try:
                    server = PageServer(gate, trials.request, trials.state, {"tasks": tasks}, args.port,
                                        host=host, tls=tls)
                except OSError as e:
                    return fail("try", f"--port: {e}")
                with server:
                    print(f"sctd try: open {server.url} (Zenoh {hub}); trials recorded in {out}",
                          file=sys.stderr, flush=True)
                    try:
                        stop.wait()
                    except KeyboardInterrupt:
                        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
    print("sctd try: stopped", file=sys.stderr, flush=True)
    return EXIT_OK
