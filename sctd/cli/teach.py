"""``sctd teach``: demonstrations shown on the simulated arm and recorded, on this machine.

Starts ``sctd sim --task TASK`` on a free loopback port (unless ``--connect`` or
``--zenoh-config`` names a running simulator to join), then the demonstrator
(:func:`sctd_services.teach.teach`): it moves the arm itself, with the variation a
person shows between demonstrations, records each one, keeps those that succeed in the
scene (``demo_NNN.csv`` in ``--out``, published on ``sctd/<robot>/demos/<task>/<name>``)
and discards the others, saying why. One line per attempt, then a summary; exit 0 when
``--demos`` were kept, 1 when the attempts ran out first or the simulator failed, 2 for
bad flags or when a shared-control daemon already commands the robot.

:func:`open_simulator` and :func:`teach_demos` are the steps, for a command that goes on
from the kept demonstrations (learning them) with the simulator still running.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh

from sctd.task import Task, add_to_path
from sctd_services.record import LINGER, check_demos_folder
from sctd_services.teach import (
    Attempt,
    CommanderConflict,
    SimulatorLost,
    TeachOptions,
    WrongScene,
    describe_outcome,
    teach,
)

from ..app.defaults import defaults
from ..app.errors import EXIT_FAILED, EXIT_OK, EXIT_USAGE, fail
from ..app.logs import log_folder
from ..app.options import add_arguments, add_task_argument, from_namespace
from ..wire import Keys
from ..wire.session import add_zenoh_arguments, session
from .procs import Child, free_port, kill_children
from .teach_loop import (
    LoopError,
    add_then_learn_arguments,
    evaluate_taught,
    learn_and_swap,
    print_reply,
    start_learner,
)

STATE_INGRESS = 250.0  # Hz of the simulator's state that teaching takes in

def add_teach_arguments(p: argparse.ArgumentParser) -> None:
    own_default = ("out", "max_attempts", "mistakes")  # their help says what the default does
    add_task_argument(p, defaults().task, help="the task to demonstrate: a name sctd tasks lists, or a "
                                               "task file (the simulator's scene)")
    add_arguments(p, TeachOptions, exclude=(*own_default, "task"), show_default=True)
    add_arguments(p, TeachOptions, only=own_default)
    p.add_argument("--logs", metavar="DIR",
                   help="keep the simulator's log (and the learner's and daemon's) in this folder "
                        "(default: a temporary one)")
    add_then_learn_arguments(p)
    add_zenoh_arguments(p)
    p.epilog = ("Without --connect or --zenoh-config, it starts its own simulator on a free "
                "loopback port. " + (p.epilog or ""))


STOP_GRACE = 10.0  # s a stop may take to unwind before the process exits at once


class _Stop:
    """SIGTERM or SIGINT (Ctrl-C): unwind, stopping the simulator, the learner and the
    daemon on the way out and discarding the attempt in progress. A second signal, or
    ``STOP_GRACE`` s without getting out (the main thread blocked in a call that does
    not return), exits at once, the children killed: a stop never hangs."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def install(self) -> None:
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, self)

    def __call__(self, signum: int, _frame: object) -> None:
        if self.signum is not None:
            self._now(f"a second {signal.Signals(signum).name}")
        self.signum = signum
        threading.Thread(target=self._watch, name="stop-watch", daemon=True).start()
        raise SystemExit(128 + signum)

    def _watch(self) -> None:
        time.sleep(STOP_GRACE)
        assert self.signum is not None
        self._now(f"still stopping {STOP_GRACE:g} s after {signal.Signals(self.signum).name}")

    def _now(self, why: str) -> None:
        killed = kill_children()
        print(f"sctd teach: {why}: exiting now ({killed} child process(es) killed); the "
              "demonstrations kept so far stay where they are", file=sys.stderr, flush=True)
        os._exit(128 + (self.signum or signal.SIGTERM))


def _kept_files(out: Path) -> set[Path]:
    return set(out.glob("demo_*.csv")) if out.is_dir() else set()


def main_teach(args: argparse.Namespace) -> int:
    stop = _Stop()
    stop.install()
    try:
        return _main_teach(args)
    except SystemExit:
        if stop.signum is None:
            raise
        return 128 + stop.signum


def _main_teach(args: argparse.Namespace) -> int:
    try:
        options = from_namespace(TeachOptions, args)
    except ValueError as e:
        return fail("teach", str(e))
    if args.swap and not args.then_learn:
        return fail("teach", "--swap: needs --then-learn METHOD")
    try:
        check_demos_folder(options.out_dir, options.the_task.object)
    except ValueError as e:
        return fail("teach", f"--out: {e}")
    add_to_path(options.task)  # the learner and the evaluation find a task file by its name
    before = _kept_files(options.out_dir)
    try:
        with contextlib.ExitStack() as stack:
            done = _teach(args, options, stack)
    except SystemExit:
        new = sorted(_kept_files(options.out_dir) - before)
        print(f"sctd teach: stopped; kept {len(new)} demonstration(s) in {options.out_dir}"
              + (f" ({', '.join(p.name for p in new)})" if new else "")
              + "; the attempt in progress was discarded", file=sys.stderr, flush=True)
        raise
    if isinstance(done, int):
        return done
    kept, reply = done
    if len(kept) < options.demos:
        return fail("teach", f"kept {len(kept)} of the {options.demos} demonstrations asked for in "
                             f"{options.attempts} attempts (--max-attempts)", EXIT_FAILED)
    if reply is None:
        return EXIT_OK
    print_reply(reply)
    if reply.get("passed") and args.eval_trials > 0:
        evaluate_taught(reply, options.name, args.then_learn, args.eval_trials)
    return EXIT_OK if reply.get("swapped") or (reply.get("passed") and not args.swap) else EXIT_FAILED


def _teach(args: argparse.Namespace, options: TeachOptions, stack: contextlib.ExitStack
           ) -> int | tuple[list[Attempt], dict[str, Any] | None]:
    """The simulator (and the learner) on ``stack``, the demonstrations taught, then
    learned and swapped when asked: (the kept attempts, the learner's reply), or an
    exit code."""
    reply = None
    try:
        s = open_simulator(stack, args, options)
        watch = start_learner(stack, s, args, args.logdir) if args.then_learn else None
        kept = teach_demos(s, options, _gone(getattr(args, "sim_child", None)))
        if watch is not None and len(kept) == options.demos:
            reply = learn_and_swap(stack, s, args, options.name, kept, watch, args.logdir)
    except (CommanderConflict, WrongScene) as e:
        return fail("teach", str(e), EXIT_USAGE)
    except (SimulatorLost, LoopError) as e:
        return fail("teach", f"{e}{_log_hint(args)}", EXIT_FAILED)
    return kept, reply


def open_simulator(stack: contextlib.ExitStack, args: argparse.Namespace,
                   options: TeachOptions) -> zenoh.Session:
    """The session teaching goes through, entered on ``stack``: connected to the
    simulator ``--connect`` / ``--zenoh-config`` names, else to a ``sctd sim --task``
    started here on a free loopback port (stopped when ``stack`` closes, after the
    session, which lingers a moment so that the last demonstration leaves)."""
    logdir = args.logdir = log_folder(args.logs, "sctd-teach-")
    # the newest state is what teaching reads (paced at 250 Hz, rows at 100 Hz): Zenoh
    # drops the rest of the simulator's 1 kHz on arrival, so that on a busy machine the
    # Python callbacks never fall behind into a backlog of seconds-old states
    ingress = [(Keys(options.robot).state, STATE_INGRESS)]
    if args.connect or args.zenoh_config:
        s = stack.enter_context(session(args.listen, args.connect, args.zenoh_config, ingress))
        args.child_zenoh = (["--zenoh-config", args.zenoh_config] if args.zenoh_config
                            else [x for ep in args.connect for x in ("--connect", ep)])
        print(f"sctd teach: {options.name} on the simulator at "
              f"{', '.join(args.connect or [args.zenoh_config])}", flush=True)
    else:
        args.sim_log = logdir / "sim.log"
        ep = f"tcp/127.0.0.1:{free_port()}"
        args.child_zenoh = ["--connect", ep]  # how the learner and the daemon join it
        args.sim_child = stack.enter_context(Child("sctd_sim.service", "--task", options.task, "--robot",
                                                   options.robot, "--listen", ep, log=args.sim_log))
        s = stack.enter_context(session(args.listen, [ep], rate_limits=ingress))
        print(f"sctd teach: {options.name} on a simulator started at {ep} (log {args.sim_log})",
              flush=True)
    stack.callback(time.sleep, LINGER)  # runs before the session closes
    return s


def _gone(child: Child | None) -> Callable[[], str | None] | None:
    """Why the simulator ``child`` (started here) is no more: its exit code and the last
    line it wrote (its own error: a start out of reach, a bad task file); None while it
    runs."""
    if child is None:
        return None

    def why() -> str | None:
        if child.running():
            return None
        lines = [ln for ln in child.output().splitlines() if ln.strip()]
        said = f": {lines[-1].strip()}" if lines else ""
        return f"the simulator exited ({child.p.returncode}){said}"
    return why


def teach_demos(s: zenoh.Session, options: TeachOptions,
                gone: Callable[[], str | None] | None = None) -> list[Attempt]:
    """Teach with ``options``, printing a line per attempt and the summary; the kept
    attempts (``Attempt.path``: the CSV). ``gone``: :func:`_gone` of a simulator started
    here."""
    out = options.out_dir
    before = len(list(out.glob("demo_*.csv"))) if out.is_dir() else 0
    print(f"sctd teach: {options.demos} demonstrations (seed {options.seed}) into {out}"
          + (f", after the {before} already there" if before else ""), flush=True)
    seen: list[Attempt] = []

    def report(a: Attempt) -> None:
        seen.append(a)
        _print_attempt(a, options.the_task)
    t0 = time.monotonic()
    kept = teach(s, options, on_attempt=report, gone=gone)
    wall = time.monotonic() - t0
    recorded = sum(a.duration for a in kept) / len(kept) if kept else 0.0
    print(f"sctd teach: kept {len(kept)} of {options.demos} demonstrations in {out} "
          f"({len(seen)} attempts, {len(seen) - len(kept)} discarded) in {wall:.0f} s: "
          f"{wall / max(1, len(kept)):.1f} s per kept demonstration, {recorded:.1f} s of it "
          "recorded", flush=True)
    return kept


def _print_attempt(a: Attempt, task: Task) -> None:
    state = "kept" if a.kept else "discarded"
    what = describe_outcome(a.outcome, task) if a.kept else a.reason
    print(f"  attempt {a.number:2d}  {a.name:8s}  {state:9s}  {a.rows:5d} rows  {a.duration:5.2f} s"
          f"  {what}   ({a.plan.describe()}; {a.elapsed:.1f} s)", flush=True)


def _log_hint(args: argparse.Namespace) -> str:
    log = getattr(args, "sim_log", None)
    return f"; see {log}" if log is not None else ""

