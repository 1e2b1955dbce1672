"""``sctd bench robustness``: the daemon next to the simulator under floods, hostile
bundles and a jumping state, with the quiet run as the baseline of the same bench.

Processes, all on one free loopback port held by this (the bench's) session:
``sctd sim --scene pour`` (the Pinocchio arm at 1 kHz), ``sctd run`` (the pour skill),
and per phase a flooder (``python -m sctd.bench.robustness flood ...``). Every
figure comes from what the daemon publishes: its targets (by ``seq``, with their
``stamp``), its status (tick counters, the per-second ``recent_ms`` windows, the drop
counters) and its resident memory (``/proc``).

Phases: quiet; the fastest valid-input flood one client can send; a 10 MB garbage
flood; poses on 50k distinct object names; 20 malformed bundles; good swaps; one state
1 m away with zero input.
"""

from __future__ import annotations

import argparse
import io
import itertools
import json
import math
import os
import signal
import sys
import threading
import time
import zipfile
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import msgpack
import zenoh

from sctd.bench import run_and_report
from sctd.cli.procs import Child, free_port
from sctd.runtime import codec
from sctd.runtime.zsession import MSGPACK, add_zenoh_arguments, session, session_from_args
from sctd.skill import Bundle, bundle_from_file

KEYS = codec.Keys()
SWAPS = 10


# --- what the phases send ---------------------------------------------------------------


def malformed_bundles(skills: Path) -> list[tuple[str, bytes]]:
    """Twenty different bundles the daemon must refuse with an error reply, from the
    shipped skills in ``skills``: bytes that are not a bundle, bundles whose YAML or
    model files are broken, hostile or invalid."""
    pour = bundle_from_file(skills / "pour.yaml")
    vf = bundle_from_file(skills / "pour-vf.yaml")
    rel = next(iter(vf.files))
    bomb = io.BytesIO()
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("points.npy", b"\0" * (300 * 1024 * 1024))

    def yaml(text: str) -> bytes:
        return Bundle(pour.name, text, {}).pack()

    def edit(old: str, new: str) -> bytes:
        assert old in pour.yaml_text, old  # each case must really break the skill
        return yaml(pour.yaml_text.replace(old, new))

    def packed(**fields: Any) -> bytes:
        m = {"format": "sctd-skill-bundle", "version": 1, "name": "x.yaml", "yaml": pour.yaml_text,
             "files": {}}
        m.update(fields)
        return msgpack.packb(m, use_bin_type=True)

    def long_description(n: int) -> str:
        line = next(ln for ln in pour.yaml_text.splitlines() if ln.startswith("description:"))
        block = "description: |\n" + "".join(f"  line {k} of a long description\n" for k in range(n))
        return pour.yaml_text.replace(line + "\n", block)

    return [
        ("garbage bytes", b"\x00\xffnot msgpack at all"),
        ("a msgpack list", msgpack.packb([1, 2, 3])),
        ("truncated bundle", pour.pack()[:-40]),
        ("wrong format", packed(format="zip", version=99)),
        ("files not bytes", packed(files={"m.npz": "text"})),
        ("escaping file name", Bundle(vf.name, vf.yaml_text, {**vf.files, "../x.npz": b""}).pack()),
        ("corrupt npz", Bundle(vf.name, vf.yaml_text, {rel: b"PK\x03\x04broken"}).pack()),
        ("npz zip bomb", Bundle(vf.name, vf.yaml_text, {rel: bomb.getvalue()}).pack()),
        ("missing model file", Bundle(vf.name, vf.yaml_text, {}).pack()),
        ("deeply nested yaml", yaml("[" * 5000)),
        ("yaml syntax error", yaml("states: [a, b\nfsm: {")),
        ("duplicate keys", yaml(pour.yaml_text + "\nname: again\n")),
        ("unknown field", yaml(pour.yaml_text + "\nspeed_of_light: 3e8\n")),
        ("not a mapping", yaml("- just\n- a list\n")),
        ("negative angle", edit("max_angle: 0.10", "max_angle: -1")),
        ("empty object", edit("object: mug", "object: ''")),
        ("non-unit quaternion", edit("[0.0, 0.0, 0.12, 0.0, 0.0, 0.0, 1.0]",
                                     "[0.0, 0.0, 0.12, 0.0, 0.0, 0.0, 3.0]")),
        ("nan limit", edit("max_linear_speed: 0.10 ", "max_linear_speed: .nan ")),
        ("7 MB yaml (parsed)", yaml(long_description(200_000))),
        ("10 MB yaml (too big)", yaml(long_description(300_000))),
    ]


def flood_main(argv: list[str]) -> int:
    """A flooder: ``garbage`` (10 MB messages on input), ``valid`` (the fastest stream
    of valid zero-input messages this process can put) or ``objects`` (valid poses on
    ``--names`` distinct object names). Prints ``{"sent": n, "seconds": s}``."""
    p = argparse.ArgumentParser(prog="sctd-bench-flood")
    p.add_argument("kind", choices=("garbage", "valid", "objects"))
    p.add_argument("--seconds", type=float, default=5.0)
    p.add_argument("--size", type=int, default=10 * 1024 * 1024)
    p.add_argument("--names", type=int, default=50_000)
    add_zenoh_arguments(p)
    args = p.parse_args(argv)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    sent = 0
    with session_from_args(args) as s:
        time.sleep(1.0)  # routes to the daemon's subscribers
        t0 = time.monotonic()
        end = t0 + args.seconds
        if args.kind == "garbage":
            pub = s.declare_publisher(KEYS.input("flood"), encoding=MSGPACK)
            blob = os.urandom(args.size)
            while time.monotonic() < end and not stop.is_set():
                pub.put(blob)
                sent += 1
        elif args.kind == "valid":
            pub = s.declare_publisher(KEYS.input("flood"), congestion_control=zenoh.CongestionControl.DROP,
                                     encoding=MSGPACK)
            batch: list[bytes] = []
            while not stop.is_set():
                if sent % 2000 == 0:  # fresh stamps, so every message is valid on arrival
                    if time.monotonic() >= end:
                        break
                    now = time.time()
                    batch = [codec.encode_input(sent + k, now, (0.0, 0.0, 0.0)) for k in range(2000)]
                pub.put(batch[sent % 2000])
                sent += 1
        else:
            for k in range(args.names):
                s.put(KEYS.objects(f"flood{k}"), codec.encode_object(k, time.time(), [0, 0, 0, 0, 0, 0, 1]),
                      encoding=MSGPACK)
                sent += 1
        seconds = time.monotonic() - t0
        time.sleep(0.2)
    print(json.dumps({"sent": sent, "seconds": round(seconds, 3)}), flush=True)
    return 0


# --- the bench's view of the daemon ----------------------------------------------------


class _Watch:
    """Targets (seq, stamp, position) and status windows, as the daemon publishes them.
    A context manager owning its subscriptions."""

    def __init__(self, s: zenoh.Session):
        self.lock = threading.Lock()
        self.targets: list[tuple[int, float, list[float], str]] = []
        self.status: dict | None = None
        self.windows: list[tuple[float, dict]] = []  # (bench time, recent_ms)
        self.state: dict | None = None
        self._stack = ExitStack()
        self.state_ring = self._stack.enter_context(
            s.declare_subscriber(KEYS.state, zenoh.handlers.RingChannel(1)))
        self._stack.enter_context(s.declare_subscriber(KEYS.target, self._on_target))
        self._stack.enter_context(s.declare_subscriber(KEYS.status, self._on_status))

    def __enter__(self) -> _Watch:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()

    def _on_target(self, sample: zenoh.Sample) -> None:
        m = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
        with self.lock:
            self.targets.append((m["seq"], m["stamp"], m["pose"][:3], m["skill"]))

    def _on_status(self, sample: zenoh.Sample) -> None:
        m = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
        with self.lock:
            recent = m.get("recent_ms")
            if recent is not None and (not self.windows or self.windows[-1][1] != recent):
                self.windows.append((time.monotonic(), recent))
            self.status = m

    def last_state(self) -> dict | None:
        s = self.state_ring.try_recv()
        if s is not None:
            self.state = msgpack.unpackb(s.payload.to_bytes(), raw=False)
        return self.state

    def snapshot(self) -> dict:
        with self.lock:
            return dict(self.status or {})



def _rss_kib(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


def _phase(w: _Watch, daemon_pid: int, run, settle: float = 1.2) -> dict:
    """Run ``run()`` and report what the daemon did meanwhile: tick counters, targets
    (rate from their own stamps, largest gap between consecutive ones), the worst and
    median per-second lateness window, drop counters, memory."""
    s0, rss0 = w.snapshot(), _rss_kib(daemon_pid)
    t0 = time.monotonic()
    with w.lock:
        k0 = len(w.targets)
    extra = run() or {}
    time.sleep(settle)  # the last second's window reaches a status message
    t1 = time.monotonic()
    s1, rss1 = w.snapshot(), _rss_kib(daemon_pid)
    with w.lock:
        tg = w.targets[max(0, k0 - 1):]  # from the last target before the phase
        windows = [r for (t, r) in w.windows if t0 + 1.0 < t <= t1]
    tg.sort()
    gaps = [b[1] - a[1] for a, b in itertools.pairwise(tg) if b[0] == a[0] + 1]
    rate = (tg[-1][0] - tg[0][0]) / (tg[-1][1] - tg[0][1]) if len(tg) > 1 and tg[-1][1] > tg[0][1] else 0.0
    p99s = sorted(win["lateness"]["p99"] for win in windows)
    drops0, drops1 = s0.get("dropped", {}), s1.get("dropped", {})
    c0, c1 = s0.get("counters", {}), s1.get("counters", {})
    return {
        "seconds": round(t1 - t0, 2),
        "ticks": s1.get("ticks", 0) - s0.get("ticks", 0),
        "late_ticks": s1.get("late_ticks", 0) - s0.get("late_ticks", 0),
        "skipped_ticks": s1.get("skipped_ticks", 0) - s0.get("skipped_ticks", 0),
        "target_rate_hz": round(rate, 1),
        "max_target_gap_ms": round(max(gaps) * 1e3, 3) if gaps else None,
        "lateness_p99_ms_worst_window": p99s[-1] if p99s else None,
        "lateness_p99_ms_median_window": p99s[len(p99s) // 2] if p99s else None,
        "lateness_max_ms": max((win["lateness"]["max"] for win in windows), default=None),
        "dropped": {k: v - drops0.get(k, 0) for k, v in drops1.items() if v != drops0.get(k, 0)},
        "counters": {k: v - c0.get(k, 0) for k, v in c1.items() if v != c0.get(k, 0)},
        "rss_growth_kib": rss1 - rss0,
        "targets": tg,
        **extra,
    }


class _Phases:
    """What each phase does next to the running daemon, through the bench's session."""

    def __init__(self, s: zenoh.Session, watch: _Watch, hub: str, skills: Path, seconds: float,
                 logdir: Path):
        self.s, self.watch, self.hub = s, watch, hub
        self.skills, self.seconds, self.logdir = skills, seconds, logdir

    def quiet(self) -> dict:
        time.sleep(self.seconds)
        return {}

    def flood(self, kind: str, *extra: str) -> dict:
        with Child("sctd.bench.robustness", "flood", kind, "--seconds", str(self.seconds),
                   "--connect", self.hub, *extra, log=self.logdir / f"flood-{kind}.log") as f:
            f.p.wait(timeout=self.seconds + 120)
        lines = [ln for ln in f.output().splitlines() if ln.startswith("{")]
        got = json.loads(lines[-1]) if lines else {"sent": 0, "seconds": 0.0}
        return {"sent": got["sent"], "sent_per_s": round(got["sent"] / max(got["seconds"], 1e-9))}

    def bad_bundles(self) -> dict:
        replies = errors = 0
        for _name, payload in malformed_bundles(self.skills):
            got = list(self.s.get(KEYS.skill, payload=payload, timeout=60.0))
            replies += len(got)
            errors += sum(1 for r in got if r.err is not None)
        return {"bundles": 20, "replies": replies, "error_replies": errors}

    def swaps(self) -> dict:
        paths = (self.skills / "pour-vf.yaml", self.skills / "pour.yaml")
        ok = 0
        windows = []  # (query sent, reply + 5 ms), wall clock as the targets' stamps
        for k in range(SWAPS):
            b = bundle_from_file(paths[k % 2])
            t0 = time.time()
            got = list(self.s.get(KEYS.skill, payload=b.pack(), timeout=30.0))
            windows.append((t0, time.time() + 0.005))
            ok += sum(1 for r in got if r.ok is not None)
            time.sleep(0.3)
        return {"swaps": SWAPS, "ok_replies": ok, "windows": windows}

    def far_state(self) -> dict:
        def jumps() -> int:
            return self.watch.snapshot().get("counters", {}).get("state_discontinuity", 0)

        before = jumps()
        for _ in range(40):  # again only if the state key's rate limit dropped it
            st = self.watch.last_state()
            assert st is not None
            pose = list(st["pose"])
            pose[0] += 1.0
            self.s.put(KEYS.state, codec.encode_state(st["seq"] + 1, time.time(), pose), encoding=MSGPACK)
            time.sleep(0.1)
            if jumps() > before:
                break
        time.sleep(max(2.0, self.seconds / 2))
        return {}


def run_robustness_bench(skills: Path, seconds: float, logdir: Path) -> dict:
    hub = f"tcp/127.0.0.1:{free_port()}"
    out: dict[str, Any] = {"seconds_per_phase": seconds}
    with session(listen=[hub]) as s, \
            Child("sctd.cli.main", "sim", "--scene", "pour", "--connect", hub, "--listen",
                  f"tcp/127.0.0.1:{free_port()}", log=logdir / "sim.log"), \
            Child("sctd.cli.main", "run", "--skill", str(skills / "pour.yaml"), "--connect", hub,
                  "--listen", f"tcp/127.0.0.1:{free_port()}", "--stats-json",
                  log=logdir / "daemon.log") as daemon, \
            _Watch(s) as w:
        end = time.monotonic() + 90
        while len(w.targets) < 2000:
            if time.monotonic() > end or not daemon.running():
                raise RuntimeError(f"the daemon published no targets; see {logdir}")
            time.sleep(0.1)
        pid = daemon.p.pid
        ph = _Phases(s, w, hub, skills, seconds, logdir)
        for name, run in (("quiet", ph.quiet), ("valid_flood", lambda: ph.flood("valid")),
                          ("garbage_flood", lambda: ph.flood("garbage")),
                          ("object_names", lambda: ph.flood("objects", "--names", "50000")),
                          ("bad_bundles", ph.bad_bundles), ("good_swaps", ph.swaps),
                          ("far_state", ph.far_state)):
            out[name] = _phase(w, pid, run)
    return out


def summarise(r: dict) -> dict:
    """The figures and their targets; drops the raw target lists."""
    bound_m = 0.1 * 1e-3  # the pour skill: 0.1 m/s per 1 kHz tick
    sw = r["good_swaps"]
    tg, windows = sw["targets"], sw.pop("windows")
    gaps = [b[1] - a[1] for a, b in itertools.pairwise(tg)
            if b[0] == a[0] + 1 and any(t0 <= a[1] <= t1 for t0, t1 in windows)]
    sw["max_gap_at_swaps_ms"] = round(max(gaps) * 1e3, 3) if gaps else None
    far = r["far_state"]
    tg = far.pop("targets")
    steps = [math.dist(a[2], b[2]) / (b[0] - a[0]) for a, b in itertools.pairwise(tg)]
    far["max_step_per_tick_mm"] = round(max(steps) * 1e3, 6) if steps else None
    for phase in r.values():
        if isinstance(phase, dict):
            phase.pop("targets", None)
    q = r["quiet"]["lateness_p99_ms_worst_window"] or 0.0
    vf = r["valid_flood"]["lateness_p99_ms_worst_window"] or 0.0
    g = r["garbage_flood"]
    r["criteria"] = {
        "garbage flood: targets >= 995 Hz": g["target_rate_hz"] >= 995,
        "garbage flood: no skipped tick": g["skipped_ticks"] == 0,
        "valid flood: lateness p99 <= 0.5 ms": vf <= 0.5,
        "valid flood: lateness p99 <= 2 x quiet (or within one 5 us bin)": vf <= max(2 * q, q + 0.005),
        "50k object names: RSS growth <= 5 MB": r["object_names"]["rss_growth_kib"] <= 5 * 1024,
        "20 malformed bundles: 20 error replies": r["bad_bundles"]["error_replies"] == 20,
        "good swaps: no gap between targets over 2 ms": (sw["max_gap_at_swaps_ms"] or 99) <= 2.0,
        "state 1 m away, zero input: no step above the bound":
            far["max_step_per_tick_mm"] is not None and far["max_step_per_tick_mm"] <= bound_m * 1e3,
    }
    return r


def print_report(r: dict) -> None:
    print(f"sctd bench robustness: pour skill next to the Pinocchio sim at 1 kHz, "
          f"{r['seconds_per_phase']:.0f} s per flood")
    cols = ("ticks", "late_ticks", "skipped_ticks", "target_rate_hz", "max_target_gap_ms",
            "lateness_p99_ms_worst_window", "lateness_p99_ms_median_window", "lateness_max_ms",
            "rss_growth_kib")
    print("  phase            " + "  ".join(f"{c.replace('_ms', '').replace('lateness_', 'late ')[:16]:>16s}"
                                         for c in cols))
    for name in ("quiet", "valid_flood", "garbage_flood", "object_names", "bad_bundles", "good_swaps",
                 "far_state"):
        ph = r[name]
        vals = "  ".join(f"{'-' if ph.get(c) is None else ph[c]!s:>16s}" for c in cols)
        print(f"  {name:16s} {vals}")
    for name in ("valid_flood", "garbage_flood", "object_names"):
        print(f"  {name}: sent {r[name]['sent']} ({r[name]['sent_per_s']}/s); dropped {r[name]['dropped']}")
    b = r["bad_bundles"]
    print(f"  bad_bundles: {b['bundles']} sent, {b['replies']} replies, {b['error_replies']} errors; "
          f"counters {b['counters']}")
    sw = r["good_swaps"]
    print(f"  good_swaps: {sw['ok_replies']} of {sw['swaps']} swapped (pour <-> pour-vf); largest gap "
          f"between targets from each query to its reply: {sw['max_gap_at_swaps_ms']} ms (quiet "
          f"phase, whole phase: {r['quiet']['max_target_gap_ms']} ms)")
    f = r["far_state"]
    print(f"  far_state: counters {f['counters']}; largest target step per tick "
          f"{f['max_step_per_tick_mm']} mm (bound 0.1 mm)")
    mark = {True: "met", False: "NOT met"}
    for k, v in r["criteria"].items():
        print(f"  {k}: {mark[v]}")


def add_robustness_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seconds", type=float, default=5.0, help="length of each flood, s")
    p.add_argument("--skills", default="skills", help="folder of the shipped skills")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def main_robustness(args: argparse.Namespace) -> int:
    return run_and_report("robustness", args, lambda logdir: summarise(
        run_robustness_bench(Path(args.skills), args.seconds, logdir)), print_report)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "flood":
        sys.exit(flood_main(sys.argv[2:]))
    print("usage: python -m sctd.bench.robustness flood garbage|valid|objects [...]", file=sys.stderr)
    sys.exit(2)
