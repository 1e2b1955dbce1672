"""``sctd bench cost``: what the daemon and the simulator cost a computer, and the lockstep
step, for this code and for a baseline measured in the same run, interleaved.

The baseline (``--baseline``) is another sctd source tree: a folder (a checkout, e.g.
``git worktree add /tmp/base v0.3``) or a commit of this checkout's repository
(exported with ``git archive`` into a temporary folder). Its programs run with its own
packages first on ``PYTHONPATH`` (the folders mapped to import names as the installed
package maps them), on this interpreter and its libraries. Without one, only this code
is measured.

Per configuration (skill x input x spin x rate), for each tree in turn (the order
alternates from one configuration to the next, so that a drift of the machine does not
favour one), one **phase**: ``sctd sim --task T`` and ``sctd run --skill S --spin-us N
--rate R`` on a private loopback port, a person's input at 100 Hz (``zero``: centred sticks, the
deadman released; ``full``: sines over the whole range on three axes, the deadman held),
``--warmup`` s, then ``--window`` s measured:

- **CPU**: user + system time from ``/proc`` of each program's whole process tree
  (every thread: the tick, Zenoh's, the daemon's skill server and worker processes), as
  a share of one core over the window;
- **lateness** and **compute**: the median, over the window's seconds, of the p99 that
  the daemon's ``status`` reports for each second (``recent_ms``; as ``sctd bench view``);
- **latency**: input to target (from sending input ``seq`` to the first target whose
  ``in_seq`` names it), p50 and p99 over the window.

With ``--floor``, also the transport's floor in one more phase (this tree's simulator): a
bare Zenoh peer in place of the daemon that drains and decodes the 1 kHz state and encodes
and puts a target every millisecond, nothing else (what any 1 kHz Python process on Zenoh
that reads the arm and commands it pays here). The daemon's goal is a ratio to it
(:data:`FLOOR_RATIO`, at the 1 kHz both run at by default), and each phase says where the
daemon's CPU went, thread by thread (:func:`thread_cpu`).

``--rates`` runs the daemon at lower tick rates too (the simulator, and the floor, stay at
1 kHz): what a computer short of CPU saves by commanding the arm less often, with the
latency it adds (docs/sizing.md).

The **tick path** (``--tick-ticks``): the daemon's tick thread's own work in one process,
from bytes and without Zenoh (:mod:`.tickpath`), back to back and after the sleep a 1 kHz
tick thread takes between ticks (:data:`TICK_SLEEPS_US`), for each skill and input in
each tree, and the floor peer's per-tick work the same way: CPU microseconds a tick,
steadier than the phases' shares of a core, and what says how much of the daemon's cost
is the sleep's (docs/benchmarks.md).

And the **lockstep step**: ``sctd bench eval`` (``--eval-trials`` trials of each skill,
the same seeds) in each tree, ms of wall time per simulated 1 kHz step.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from ..app.defaults import defaults
from ..cli.procs import Child, free_port
from ..timing import RoundTrips, Ticker, set_timer_slack
from ..wire import Keys, codec
from ..wire.session import session
from . import run_and_report
from .latency import wait_for_targets
from .parts import PARTS, PartClock, per_tick, write_parts

SET = "set:"  # a --skills entry that names a skill set

IMPORT_FOLDERS = {"sctd": "sctd", "sctd_sim": "sim", "sctd_services": "services",
                  "sctd_skills": "skills", "sctd_tasks": "tasks"}
"""Import name -> folder of a source tree (as the package installs them)."""

GOALS = {"lateness_ms": 0.2}
"""The absolute figures this bench is judged by (ms). The simulator's share of a core and
the lockstep step are printed without a goal: an absolute goal for them (20 % of a core,
0.12 ms a step) was set before their floors were measured, and is out of Python's reach
(docs/benchmarks.md)."""
FLOOR_RATIO = 1.5
"""The daemon with the spin off (``--spin-us 0``) at 1 kHz, every skill and input, at most
this many times the floor's CPU measured in the same run (the floor's bare peer pays
Zenoh, the decoding and the encoding; what is left is the runtime's own)."""
RATE = 1000.0  # Hz: the daemon's default tick rate, the simulator's and the floor's

INPUT_RATE = 100.0  # Hz of the bench's person


@dataclass(frozen=True)
class Tree:
    """One source tree's programs: ``label`` and the environment they run in (None: this
    process's own)."""

    label: str
    env: dict[str, str] | None = None
    source: str = ""  # what the baseline was made from
    cwd: Path | None = None  # where its programs start: ``python -m`` puts it first on sys.path


def source_tree(spec: str, stack: ExitStack) -> Tree:
    """The baseline tree named by ``spec``: a folder holding ``sctd/`` and ``sim/``, or a
    commit of the repository this code was loaded from. Temporary folders are removed
    by ``stack``.

    Raises
    ------
    RuntimeError
        Neither a source folder nor a commit ``git`` knows here.
    """
    folder = Path(spec).expanduser()
    label = spec
    if not folder.is_dir():
        folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="sctd-baseline-")))
        repo = Path(__file__).resolve().parents[2]
        try:
            archive = subprocess.run(["git", "-C", str(repo), "archive", "--format=tar", spec],
                                     capture_output=True, check=True, timeout=60).stdout
            subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True, timeout=60)
        except (OSError, subprocess.SubprocessError) as e:
            why = getattr(e, "stderr", b"") or b""
            raise RuntimeError(f"--baseline {spec!r}: not a folder, and not a commit of {repo} "
                               f"({why.decode(errors='replace').strip() or e})") from None
    missing = [f for f in IMPORT_FOLDERS.values() if not (folder / f).is_dir()]
    if missing:
        raise RuntimeError(f"--baseline {spec!r}: {folder} is not an sctd source tree (no "
                           f"{', '.join(missing)})")
    links = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="sctd-baseline-path-")))
    for name, sub in IMPORT_FOLDERS.items():
        (links / name).symlink_to(folder.resolve() / sub, target_is_directory=True)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(links), env.get("PYTHONPATH", "")]))
    return Tree("baseline", env, label, links)


# --- CPU from /proc ---------------------------------------------------------------------

def _descendants(pid: int) -> list[int]:
    out = [pid]
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return []
    for t in tasks:
        try:
            with open(f"/proc/{pid}/task/{t}/children") as f:
                kids = [int(k) for k in f.read().split()]
        except OSError:
            continue
        for k in kids:
            out += _descendants(k)
    return out


def tree_cpu(pid: int) -> tuple[float, int]:
    """User + system seconds so far of process ``pid`` and every process under it, and
    the times their threads have slept (voluntary context switches: wake-ups)."""
    total = sleeps = 0
    for p in _descendants(pid):
        try:
            with open(f"/proc/{p}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            for t in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{t}/status") as f:
                    sleeps += next(int(line.split()[1]) for line in f
                                   if line.startswith("voluntary_ctxt_switches"))
        except (OSError, StopIteration, ValueError):
            continue  # ended meanwhile
        total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK"), sleeps


def thread_cpu(pid: int) -> dict[str, float]:
    """User + system seconds so far of each thread of process ``pid`` and of the processes
    under it, by what it is: ``main`` (the process's first thread: the daemon's tick),
    ``python`` (its other Python threads, which the kernel names after the interpreter),
    Zenoh's runtime threads by their own names with the number dropped (``rx``, ``tx``,
    ``net``, ``acc``, ``app``), and ``child <name>`` for a process under it (the skill
    server's, a worker's), all its threads together."""
    out: dict[str, float] = {}
    tick = os.sysconf("SC_CLK_TCK")
    for p in _descendants(pid):
        try:
            tasks = os.listdir(f"/proc/{p}/task")
        except OSError:
            continue
        for t in tasks:
            try:
                with open(f"/proc/{p}/task/{t}/stat") as f:
                    head, rest = f.read().rsplit(")", 1)
            except OSError:
                continue  # ended meanwhile
            comm, fields = head.split("(", 1)[1], rest.split()
            if p != pid:
                label = f"child {_process_name(p)}"
            elif int(t) == pid:
                label = "main"
            elif comm.startswith("python"):
                label = "python"
            else:
                label = comm.rstrip("0123456789").rstrip("-") or comm
            out[label] = out.get(label, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return out


def _process_name(pid: int) -> str:
    """A process's name for :func:`thread_cpu`: its module (``python -m M``) or its command."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            argv = [a.decode(errors="replace") for a in f.read().split(b"\0") if a]
    except OSError:
        return "?"
    if "-m" in argv[:-1]:
        return argv[argv.index("-m") + 1]
    return os.path.basename(argv[0]) if argv else "?"


def threads_between(before: dict[str, float], after: dict[str, float], dt: float) -> dict[str, float]:
    """Each label's share of one core between two :func:`thread_cpu` readings ``dt`` s
    apart, largest first."""
    shares = {k: round((after.get(k, 0.0) - before.get(k, 0.0)) / dt, 4) for k in after}
    return dict(sorted(shares.items(), key=lambda kv: -kv[1]))


# --- one phase ----------------------------------------------------------------------------

class _Seconds:
    """The daemon's per-second p99s of lateness and compute, with their arrival times."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, float, float]] = []
        self._lock = threading.Lock()

    def __call__(self, sample: zenoh.Sample) -> None:
        try:
            recent = codec.unpack_map(sample.payload.to_bytes()).get("recent_ms") or {}
            row = (time.monotonic(), float(recent["lateness"]["p99"]), float(recent["compute"]["p99"]))
        except (KeyError, TypeError, ValueError, codec.DecodeError):
            return
        with self._lock:
            if not self.rows or row[0] - self.rows[-1][0] >= 0.95:
                self.rows.append(row)

    def between(self, t0: float, t1: float) -> list[tuple[float, float, float]]:
        with self._lock:
            return [r for r in self.rows if t0 <= r[0] <= t1]


def _person(ep: str, full: bool, trips: RoundTrips, stop: threading.Event) -> None:
    """The bench's person at :data:`INPUT_RATE`: centred and released, or full sines with
    the deadman held; every send timed for the latency."""
    with session(connect=[ep]) as s:
        pub = s.declare_publisher(Keys().input("bench"))
        k = 0
        while not stop.is_set():
            k += 1
            u = [math.sin(k * 0.013), math.cos(k * 0.009), math.sin(k * 0.005)] if full else [0.0] * 3
            trips.sent(k)
            pub.put(codec.encode_input(k, time.time(), u, [0, 1 if full else 0, 0]))
            stop.wait(1.0 / INPUT_RATE)
        pub.put(codec.encode_input(k + 1, time.time(), [0.0, 0.0, 0.0], [0, 0, 0]))


@dataclass(frozen=True)
class Phase:
    """One phase's configuration (module doc); ``floor``: the bare peer instead of the
    daemon."""

    skill: str
    task: str
    full: bool
    spin_us: float
    window: float
    warmup: float
    floor: bool = False
    rate: float = RATE  # the daemon's --rate
    parts: bool = False  # the daemon's tick thread timed part by part (.parts)

    @property
    def name(self) -> str:
        if self.floor:
            return "floor: bare Zenoh peer"
        at = "" if self.rate == RATE else f" {self.rate:g} Hz"
        return f"{self.skill} {'full' if self.full else 'zero'} spin {self.spin_us:g} us{at}"

    def daemon_argv(self, ep: str, parts_file: Path | None = None) -> tuple[str, ...]:
        """The program in the daemon's place: ``sctd run`` (or the floor's peer); with
        ``parts_file``, run with its tick's parts timed into it (:mod:`.parts`)."""
        if self.floor:
            return ("sctd.bench.cost", "floor", "--connect", ep,
                    *(() if parts_file is None else ("--parts-out", str(parts_file))))
        what = ("--set", self.skill[len(SET):]) if self.skill.startswith(SET) else ("--skill", self.skill)
        run = ("sctd.cli.main", "run") if parts_file is None else (
            "sctd.bench.parts", "--out", str(parts_file), "run")
        return (*run, *what, "--connect", ep, "--spin-us", f"{self.spin_us:g}", "--rate", f"{self.rate:g}")


def run_phase(tree: Tree, ph: Phase, logdir: Path, k: int) -> dict[str, Any]:
    """One phase of ``tree`` (module doc); its figures."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    seconds, trips, stop = _Seconds(), RoundTrips(), threading.Event()
    trips.counting = False
    parts_file = logdir / f"parts-{k}.json" if ph.parts else None
    tick = ph.daemon_argv(ep, parts_file)
    with Child("sctd.cli.main", "sim", "--task", ph.task, "--listen", ep, log=logdir / f"sim-{k}.log",
               env=tree.env, cwd=tree.cwd) as sim, \
         Child(*tick, log=logdir / f"daemon-{k}.log", env=tree.env, cwd=tree.cwd) as daemon, \
         session(connect=[ep]) as s:
        wait_for_targets(ep, daemon, logdir, timeout=90.0)
        subs = [s.declare_subscriber(Keys().status, seconds),
                s.declare_subscriber(Keys().target, lambda x: _answered(trips, x))]
        person = threading.Thread(target=_person, args=(ep, ph.full, trips, stop), daemon=True)
        person.start()
        try:
            time.sleep(ph.warmup)
            trips.counting = True
            c_sim, c_run, c_thr, t0 = (tree_cpu(sim.p.pid), tree_cpu(daemon.p.pid), thread_cpu(daemon.p.pid),
                                       time.monotonic())
            c_parts = _read_json(parts_file)
            time.sleep(ph.window)
            t1 = time.monotonic()
            e_sim, e_run, e_thr = tree_cpu(sim.p.pid), tree_cpu(daemon.p.pid), thread_cpu(daemon.p.pid)
            e_parts = _read_json(parts_file)
            trips.counting = False
            if not (sim.running() and daemon.running()):
                raise RuntimeError(f"a program ended during the phase; see {logdir}/*-{k}.log")
        finally:
            stop.set()
            person.join(5.0)
            for sub in subs:
                sub.undeclare()
    rows, dt = seconds.between(t0, t1), t1 - t0
    return {"tree": tree.label, "phase": ph.name, "skill": ph.skill, "input": "full" if ph.full else "zero",
            "spin_us": ph.spin_us, "rate": ph.rate, "floor": ph.floor,
            "daemon_cpu": round((e_run[0] - c_run[0]) / dt, 4),
            "sim_cpu": round((e_sim[0] - c_sim[0]) / dt, 4),
            "daemon_threads": threads_between(c_thr, e_thr, dt),
            "daemon_wakeups": round((e_run[1] - c_run[1]) / dt),
            "sim_wakeups": round((e_sim[1] - c_sim[1]) / dt),
            "lateness_p99_ms": _median([r[1] for r in rows]), "compute_p99_ms": _median([r[2] for r in rows]),
            "latency_ms": trips.histogram.summary_ms() if trips.histogram.n else None,
            "tick_parts": per_tick(c_parts, e_parts) if c_parts and e_parts else None}


def _read_json(path: Path | None) -> dict[str, Any] | None:
    """The JSON in ``path`` (None: no path, or nothing written there yet)."""
    try:
        return json.loads(path.read_text()) if path is not None else None
    except (OSError, ValueError):
        return None


def _answered(trips: RoundTrips, sample: zenoh.Sample) -> None:
    now = time.monotonic()
    try:
        trips.answered(int(codec.decode_target(sample.payload.to_bytes())["in_seq"]), now)
    except (KeyError, TypeError, ValueError):
        pass


def _median(xs: list[float]) -> float | None:
    return round(statistics.median(xs), 4) if xs else None


# --- the lockstep step ------------------------------------------------------------------

def lockstep_step(tree: Tree, skill: str, trials: int, logdir: Path) -> dict[str, Any]:
    """``sctd bench eval --json`` of ``skill`` in ``tree``: its figures."""
    log = logdir / f"eval-{skill}-{len(list(logdir.glob('eval-*')))}.log"
    with Child("sctd.cli.main", "bench", "eval", "--skill", skill, "--trials", str(trials), "--json",
               log=log, env=tree.env, cwd=tree.cwd) as child:
        if child.p.wait(timeout=60.0 * trials + 120.0) != 0:
            raise RuntimeError(f"sctd bench eval failed in {tree.label}; see {log}")
    out = json.loads(log.read_text().strip().splitlines()[-1])
    return {"tree": tree.label, "skill": skill, "ms_per_step": out["ms_per_step"], "rtf": out["rtf"],
            "outcomes": out["outcomes"], "sim_s": out["sim_s"]}


# --- the tick path in one process --------------------------------------------------------

TICK_SLEEPS_US = (0.0, 900.0)  # back to back, and the sleep of a 1 kHz tick thread between ticks
PROBE = "sctd_tickpath"  # this tree's .tickpath, copied, run in each tree's environment


def tick_path(tree: Tree, skill: str, task: str, inputs: list[bool], ticks: int, logdir: Path,
              path: str = "tick") -> list[dict[str, Any]]:
    """:mod:`.tickpath`'s rows for ``skill`` (``path`` ``tick``; or the floor's path, or
    the control loop) in ``tree``: this tree's probe, run on that tree's code."""
    probe = logdir / "probe"
    if not (probe / f"{PROBE}.py").exists():
        probe.mkdir(exist_ok=True)
        (probe / f"{PROBE}.py").write_text(Path(__file__).with_name("tickpath.py").read_text())
    env = dict(tree.env if tree.env is not None else os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [env.get("PYTHONPATH", ""), str(probe)]))
    what = ("--path", path, "--inputs", "zero") if path != "tick" else (
        "--inputs", ",".join("full" if x else "zero" for x in inputs))
    log = logdir / f"tickpath-{len(list(logdir.glob('tickpath-*')))}.log"
    sleeps = ",".join(f"{x:g}" for x in TICK_SLEEPS_US)
    with Child(PROBE, "--skill", skill, "--task", task, "--ticks", str(ticks), *what, "--sleeps-us", sleeps,
               log=log, env=env, cwd=tree.cwd) as c:
        if c.p.wait(timeout=120.0 + 0.01 * ticks * len(TICK_SLEEPS_US) * len(inputs)) != 0:
            raise RuntimeError(f"the tick path probe failed in {tree.label}; see {log}")
    rows = json.loads(log.read_text().strip().splitlines()[-1])["rows"]
    return [{"tree": tree.label, "skill": skill if path == "tick" else path, **{k: r[k] for k in (
        "input", "path", "sleep_us", "us_per_tick", "modes")}} for r in rows]


# --- the run --------------------------------------------------------------------------------

def phases_of(args: argparse.Namespace) -> list[Phase]:
    out = [Phase(skill, args.task, full, spin, args.window, args.warmup, rate=rate, parts=args.parts)
           for rate in args.rates for skill in args.skills for full in args.inputs for spin in args.spins]
    if args.floor:
        out.append(Phase(args.skills[0], args.task, False, 0.0, args.window, args.warmup, floor=True,
                         parts=args.parts))
    return out


def run_cost_bench(args: argparse.Namespace, logdir: Path) -> dict[str, Any]:
    """Every phase and lockstep measurement of ``args``, trees interleaved."""
    with ExitStack() as stack:
        trees = [Tree("this", cwd=logdir)]  # not a source tree's folder: its sctd would come first
        if args.baseline:
            trees.insert(0, source_tree(args.baseline, stack))
        rows: list[dict[str, Any]] = []
        for k, ph in enumerate(phases_of(args)):
            order = [trees[-1]] if ph.floor else trees if k % 2 == 0 else trees[::-1]
            for tree in order:
                rows.append(run_phase(tree, ph, logdir, len(rows)))
                print(_row(rows[-1]), file=sys.stderr, flush=True)
        ticked = [x for x in args.skills if not x.startswith(SET)] if args.tick_ticks else []
        paths: list[dict[str, Any]] = []
        for k, skill in enumerate(ticked):
            for tree in (trees if k % 2 == 0 else trees[::-1]):
                paths += tick_path(tree, skill, args.task, args.inputs, args.tick_ticks, logdir)
        for tree in trees if ticked else []:
            paths += tick_path(tree, ticked[0], args.task, [False], args.tick_ticks, logdir, path="floor")
        if ticked:
            paths += tick_path(trees[-1], ticked[0], args.task, [False], args.tick_ticks, logdir, path="loop")
        steps = []
        stepped = [x for x in args.skills if not x.startswith(SET)] if args.eval_trials else []
        for k, skill in enumerate(stepped):
            for tree in (trees if k % 2 == 0 else trees[::-1]):
                steps.append(lockstep_step(tree, skill, args.eval_trials, logdir))
    return {"task": args.task, "window_s": args.window, "trees": {t.label: t.source for t in trees},
            "phases": rows, "tick_path": paths, "lockstep": steps, "goals": GOALS}


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:5.1f}"


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.3f}"


def _row(r: dict[str, Any]) -> str:
    lat = r["latency_ms"] or {}
    return (f"  {r['phase']:<31s} {r['tree']:<9s} {_pct(r['daemon_cpu']):>7s} {r['daemon_wakeups']:>6d} "
            f"{_pct(r['sim_cpu']):>6s} {r['sim_wakeups']:>6d} "
            f"{_ms(r['lateness_p99_ms']):>9s} {_ms(r['compute_p99_ms']):>9s} "
            f"{_ms(lat.get('p50')):>7s} {_ms(lat.get('p99')):>7s}")


def print_report(r: dict[str, Any]) -> None:
    print(f"sctd bench cost: task {r['task']}, {r['window_s']:g} s windows; CPU in % of one core "
          "(each program's process tree, from /proc); lateness and compute: median of the daemon's "
          "per-second p99, ms; latency input -> target, ms; wakes: the threads' sleeps per second")
    if r["trees"].get("baseline"):
        print(f"  baseline: {r['trees']['baseline']}")
    print(f"  {'phase':<31s} {'tree':<9s} {'daemon':>7s} {'wakes':>6s} {'sim':>6s} {'wakes':>6s} "
          f"{'late p99':>9s} {'comp p99':>9s} "
          f"{'lat p50':>7s} {'lat p99':>7s}")
    for row in r["phases"]:
        print(_row(row))
        threads = row.get("daemon_threads") or {}
        if threads:
            shown = [f"{k} {100 * v:.1f}" for k, v in list(threads.items())[:8] if v >= 0.001]
            print("      threads: " + ", ".join(shown))
        parts = row.get("tick_parts")
        if parts:
            print(f"      the tick thread, us a tick: {parts['thread']:.1f} = "
                  + ", ".join(f"{p} {parts[p]:.1f}" for p in (*PARTS, "rest")))
    _print_tick_path(r.get("tick_path") or [])
    if r["lockstep"]:
        print("lockstep step (sctd bench eval, the same seeds in each tree):")
        for s in r["lockstep"]:
            outcomes = ", ".join(f"{n} {k}" for k, n in sorted(s["outcomes"].items()))
            print(f"  {s['skill']:<12s} {s['tree']:<9s} {s['ms_per_step']:.4f} ms per step, real-time factor "
                  f"{s['rtf']:.2f} ({s['sim_s']:.1f} s simulated; {outcomes})")
    for line in verdicts(r):
        print(line)


def _print_tick_path(rows: list[dict[str, Any]]) -> None:
    """The tick-path rows: per skill, input and tree, back to back / after the sleep."""
    if not rows:
        return
    slept = max(TICK_SLEEPS_US)
    print(f"tick path in one process (from bytes, no Zenoh; sctd.bench.tickpath), CPU us a tick: "
          f"back to back / after a {slept / 1000:g} ms sleep (times as much)")
    cells: dict[tuple[str, str, str], dict[float, float]] = {}
    for x in rows:
        cells.setdefault((x["skill"], x["input"], x["tree"]), {})[x["sleep_us"]] = x["us_per_tick"]
    for (skill, given, tree), by_sleep in cells.items():
        hot, cold = by_sleep.get(0.0), by_sleep.get(slept)
        name = {"floor": "floor's path", "loop": "control: a tight loop"}.get(skill, f"{skill} {given}")
        ratio = f" ({cold / hot:.1f}x)" if hot and cold else ""
        print(f"  {name:<24s} {tree:<9s} {hot if hot is not None else '-':>7} / "
              f"{cold if cold is not None else '-'}{ratio}")


def verdicts(r: dict[str, Any]) -> list[str]:
    """This code's figures against its goals (the worst phase of each kind, at 1 kHz): the
    daemon against the floor (:data:`FLOOR_RATIO`, spin off) and the lateness
    (:data:`GOALS`); then, for each lower ``--rates`` rate, the daemon's worst phase with
    the spin off against the same floor and its worst lateness, which are no goal: what
    a slower tick saves, and what it costs in timing."""
    mine = [p for p in r["phases"] if p["tree"] == "this" and not p["floor"]]
    out = []
    floor = next((p["daemon_cpu"] for p in r["phases"] if p["tree"] == "this" and p["floor"]), None)
    spin_off = [p["daemon_cpu"] for p in mine if p["spin_us"] == 0 and p.get("rate", RATE) == RATE]
    if floor and spin_off:
        worst = max(spin_off) / floor
        out.append(f"  daemon, spin off, against the floor ({100 * floor:.1f} %): worst {worst:.2f}x "
                   f"(goal <= {FLOOR_RATIO:.1f}x): {'met' if worst <= FLOOR_RATIO else 'NOT met'}")
    late = [p["lateness_p99_ms"] for p in mine
            if p["lateness_p99_ms"] is not None and p.get("rate", RATE) == RATE]
    if late:
        goal = GOALS["lateness_ms"]
        out.append(f"  lateness p99: worst {max(late):.3f} ms (goal <= {goal:.2f} ms): "
                   f"{'met' if max(late) <= goal else 'NOT met'}")
    for rate in sorted({p.get("rate", RATE) for p in mine} - {RATE}, reverse=True):
        slow = [p for p in mine if p["spin_us"] == 0 and p.get("rate", RATE) == rate]
        if floor and slow:
            cpu = max(p["daemon_cpu"] for p in slow)
            worst = max((p["lateness_p99_ms"] for p in slow if p["lateness_p99_ms"] is not None),
                        default=None)
            late_s = "" if worst is None else f", lateness p99 worst {worst:.3f} ms"
            out.append(f"  daemon at {rate:g} Hz, spin off: worst {100 * cpu:.1f} % of a core, "
                       f"{cpu / floor:.2f}x the 1 kHz floor{late_s} (no goal)")
    return ["this code against the goals:", *out] if out else []


# --- the floor's bare peer ---------------------------------------------------------------

def floor_peer(ep: str, parts_file: str | None = None) -> None:
    """Drain and decode the 1 kHz state and encode and put a target every millisecond,
    nothing else (on the daemon's keys, so that the phase's probes see it). With
    ``parts_file``, its drain and its put are timed as the daemon's parts are
    (:mod:`.parts`; the rest is its sleep and its loop)."""
    keys = Keys()
    with session(connect=[ep]) as s:
        sub = s.declare_subscriber(keys.state, zenoh.handlers.RingChannel(4))
        pub = s.declare_publisher(keys.target, express=True, congestion_control=zenoh.CongestionControl.DROP)
        set_timer_slack(1)
        ticker, seq, pose = Ticker(1e-3, spin=0.0), 0, [0.5, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0]

        def drain() -> None:
            while (x := sub.try_recv()) is not None:
                codec.decode_state(x.payload.to_bytes())

        def put(seq: int) -> None:
            pub.put(codec.encode_target(seq, time.time(), pose, "floor", "floor", 0, "", False))

        if parts_file is not None:
            clock = PartClock()
            drain, put = clock.timed("drain", drain), clock.timed("put", put)
            write_parts(parts_file, clock, ticker, threading.get_ident())
        while True:
            ticker.wait()
            drain()
            seq += 1
            put(seq)


def _csv(kind: type, what: str):
    def parse(text: str) -> list:
        try:
            out = [kind(x) for x in text.split(",") if x.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: comma-separated {what}") from None
        if not out:
            raise argparse.ArgumentTypeError(f"{text!r}: at least one {what}")
        return out
    return parse


def _inputs(text: str) -> list[bool]:
    names = [x.strip() for x in text.split(",") if x.strip()]
    bad = [n for n in names if n not in ("zero", "full")]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"{text!r}: comma-separated zero and/or full")
    return [n == "full" for n in names]


def add_cost_bench_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--baseline", metavar="DIR|COMMIT",
                   help="another sctd source tree to measure beside this one: a folder, or a commit "
                        "of this checkout's repository")
    skills = [defaults().skill, defaults().learned_skill]
    p.add_argument("--skills", type=_csv(str, "skills"), default=skills,
                   help=f"skills the daemon runs (default {','.join(skills)}); set:NAME|FILE runs a skill "
                        "set (sctd run --set; no lockstep step for it)")
    p.add_argument("--task", default=defaults().task, help="the simulator's task (default %(default)s)")
    p.add_argument("--inputs", type=_inputs, default=[False, True], help="zero,full (default both)")
    p.add_argument("--spins", type=_csv(float, "spins in us"), default=[0.0, 25.0, 50.0, 100.0],
                   help="the daemon's --spin-us values (default 0,25,50,100)")
    p.add_argument("--rates", type=_csv(float, "rates in Hz"), default=[RATE],
                   help="the daemon's --rate values, Hz (default 1000; the simulator and the floor "
                        "stay at 1000)")
    p.add_argument("--window", type=float, default=10.0, help="s measured per phase (default %(default)s)")
    p.add_argument("--warmup", type=float, default=3.0, help="s before each window (default %(default)s)")
    p.add_argument("--floor", action=argparse.BooleanOptionalAction, default=True,
                   help="also measure the bare Zenoh peer's floor (default on)")
    p.add_argument("--eval-trials", type=int, default=2,
                   help="lockstep trials per skill for the step's figure, 0: none (default %(default)s)")
    p.add_argument("--tick-ticks", type=int, default=3000,
                   help="ticks of the tick path in one process per skill, input and sleep, 0: none "
                        "(default %(default)s)")
    p.add_argument("--parts", action="store_true",
                   help="time the daemon's tick thread part by part (drain, spin, step, put, account, "
                        "status, after, the rest); this tree only")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def main_cost_bench(args: argparse.Namespace) -> int:
    if not args.window > 0 or args.warmup < 0 or args.eval_trials < 0 or args.tick_ticks < 0:
        from ..app.errors import fail

        return fail("bench cost", "--window must be > 0, --warmup, --eval-trials and --tick-ticks >= 0")
    if args.parts and args.baseline:
        from ..app.errors import fail

        return fail("bench cost", "--parts times this tree's daemon only: leave out --baseline (an "
                                  "instrumented daemon is no fair comparison with one that is not)")
    bad = [x for x in args.rates if not 0.0 < x <= RATE]
    if bad:
        from ..app.errors import fail

        return fail("bench cost", f"--rates {bad[0]:g}: a tick rate above 0 and at most the simulator's "
                                  f"{RATE:g} Hz")
    return run_and_report("cost", args, lambda logdir: run_cost_bench(args, logdir), print_report)


def main(argv: list[str] | None = None) -> int:
    """``python -m sctd.bench.cost floor --connect EP``: the floor's bare peer."""
    p = argparse.ArgumentParser(prog="sctd.bench.cost")
    p.add_argument("role", choices=["floor"])
    p.add_argument("--connect", required=True)
    p.add_argument("--parts-out", help="time the drain and the put into this file (sctd.bench.parts)")
    a = p.parse_args(argv)
    try:
        floor_peer(a.connect, a.parts_out)
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
