"""``sctd bench hostile``: hostile or careless input on every surface a user hands sctd,
and what each command did with it.

Files: each hostile file goes to the command that reads it, as its own process (input
mapping files to ``sctd input keyboard --map``, skill files and folders to ``sctd
inspect`` and ``sctd swap``, logs to ``sctd replay``); the figures are its exit code,
the first line it printed, whether that line quotes the file's content, and its peak
resident memory (the process' own ``VmHWM``).

The learner: training requests with hyperparameters out of range, a skipped check and
names that are paths, and demonstrations that are too long, misnamed or over a task's
quota; the figures are what the learner replied or said on its status.

All of it next to ``sctd sim --task``, ``sctd run`` and ``sctd learner`` (a
private store; the task and skill of ``sctd/app/defaults.yaml``, the hostile skill
folders copies of its learned skill), with the daemon's worst lateness window over a
quiet phase, while the tools read the files, and while the learner is attacked.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import msgpack
import zenoh

from sctd.app.defaults import defaults
from sctd.bench import run_and_report
from sctd.cli.procs import Child, free_port
from sctd.skill import bundle_from_file
from sctd.skill.catalog import find_skill
from sctd.task import Task, find_task
from sctd.wire import Keys, codec
from sctd.wire.session import MSGPACK, session

# The folder holding this sctd package (the checkout, or site-packages): the measured
# commands run there, so that ``python -m sctd.bench.hostile`` imports this same sctd.
IMPORT_ROOT = Path(__file__).resolve().parents[2]
MAX_RSS_MB = 300.0  # the most any command may take on any of these inputs
SECRET = "PASSWORD=hunter2-sctd-bench"  # planted in files a refusal must never quote


def run_command(args: list[str], timeout: float = 120.0) -> dict[str, Any]:
    """``sctd ARGS`` as its own process: exit code, first stderr line, peak RSS (MB: the
    process' own high-water mark, ``VmHWM``, which it writes as it exits; the kernel's
    ``ru_maxrss`` would include this bench's memory, which the child had before exec)."""
    with tempfile.TemporaryDirectory() as d:
        hwm = Path(d) / "hwm"
        with (Path(d) / "err").open("w+b") as err:
            p = subprocess.Popen([sys.executable, "-m", "sctd.bench.hostile", "measure", str(hwm), *args],
                                 stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err,
                                 cwd=IMPORT_ROOT)
            t0 = time.monotonic()
            try:
                code = p.wait(timeout)
            except subprocess.TimeoutExpired:
                p.kill()
                code = p.wait()
            err.seek(0)
            text = err.read().decode("utf-8", "replace")
        rss = int(hwm.read_text()) / 1024 if hwm.exists() else float("nan")
    first = next((ln for ln in text.splitlines() if ln.strip()), "")
    return {"exit": code, "said": first[:200], "quotes_content": SECRET in text,
            "traceback": "Traceback" in text, "rss_mb": round(rss, 1),
            "seconds": round(time.monotonic() - t0, 2)}


def measure_main(argv: list[str]) -> int:
    """``python -m sctd.bench.hostile measure FILE ARGS``: ``sctd ARGS``, then its peak
    resident memory (kB, ``VmHWM``) written to FILE as it exits."""
    import atexit

    def write_hwm() -> None:
        with open("/proc/self/status") as f:
            kb = next(int(ln.split()[1]) for ln in f if ln.startswith("VmHWM:"))
        Path(argv[0]).write_text(str(kb))

    atexit.register(write_hwm)
    from sctd.cli.main import main

    return main(argv[1:])


# --- hostile files -------------------------------------------------------------------


def _laughs() -> str:
    lines = ["version: 1", "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    for k, name in enumerate("bcdefghij"):
        lines.append(f"{name}: &{name} [" + ", ".join(["*" + "abcdefghij"[k]] * 9) + "]")
    return "\n".join(lines) + "\naxes: [{source: 0}]\n"


def map_files(d: Path) -> list[tuple[str, str]]:
    """(what, path) of hostile input mapping files."""
    def write(name: str, data: str | bytes) -> str:
        p = d / name
        p.write_bytes(data if isinstance(data, bytes) else data.encode())
        return str(p)

    secret = write("secret.txt", SECRET + "\n")
    link = d / "map-link.yaml"
    link.symlink_to(secret)
    return [
        ("duplicate key (enable: 10, enable: null)",
         write("dup.yaml", "version: 1\naxes: [{source: 0}]\nbuttons: {enable: 10, enable: null}\n")),
        ("billion laughs", write("laughs.yaml", _laughs())),
        ("/dev/zero", "/dev/zero"), ("/dev/urandom", "/dev/urandom"),
        ("a 60 MB list", write("big.yaml", "axes: [" + "{source: 0}, " * 5_000_000 + "]\n")),
        ("not UTF-8", write("latin1.yaml", b"version: 1\n# \xe9t\xe9\naxes: [{source: 0}]\n")),
        ("100,000 deep", write("deep.yaml", "[" * 100_000 + "]" * 100_000)),
        ("a symlink to a file it should not show", str(link)),
    ]


def skill_folders(d: Path, learned: Path) -> list[tuple[str, str]]:
    """(what, path) of skill files and folders that must not load: copies of the skill
    file ``learned`` (one with model files) whose model files are hostile symlinks."""
    out: list[tuple[str, str]] = []
    secret = d / "secret.npz"
    secret.write_text(SECRET + "\n")
    models = list(bundle_from_file(learned).files)  # the model files its YAML names, relative to it
    for what, target in (("model file symlinked to /dev/zero", "/dev/zero"),
                         ("model file symlinked outside its folder", str(secret))):
        f = d / f"skill-{len(out)}"
        f.mkdir()
        (f / learned.name).write_bytes(learned.read_bytes())
        for rel in models:
            (f / rel).symlink_to(target)
        out.append((what, str(f / learned.name)))
    deep = d / "deep.yaml"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    latin = d / "latin1.yaml"
    latin.write_bytes(b"sctd_skill: 1\nname: \xe9\n")
    return [*out, ("100,000 deep", str(deep)), ("not UTF-8", str(latin)), ("/dev/zero", "/dev/zero")]


def log_files(d: Path) -> list[tuple[str, str]]:
    """(what, path) of hostile ``sctd log`` files: bit flips, a wildcard topic, a JSON
    list body, a zstd bomb."""
    import zstandard
    from mcap.data_stream import RecordBuilder
    from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Message, Schema
    from mcap.writer import MCAP0_MAGIC

    from sctd.bench.fuzz import _log_seed

    def raw(name: str, *records: Any) -> str:
        b = RecordBuilder()
        b.write(MCAP0_MAGIC)
        Header(profile="", library="bench").write(b)
        for r in records:
            r.write(b)
        DataEnd(0).write(b)
        Footer(0, 0, 0).write(b)
        b.write(MCAP0_MAGIC)
        (d / name).write_bytes(b.end())
        return str(d / name)

    schema = Schema(id=1, name="s", encoding="jsonschema", data=b"{}")
    state = b'{"seq": 1, "stamp": 1.0, "pose": [0.4, 0.1, 0.9, 0, 0, 0, 1]}'
    out = [("topic state/**", raw("wild.mcap", schema, Channel(id=1, topic="sctd/edan/state/**",
                                                                  message_encoding="json", metadata={},
                                                                  schema_id=1),
                                      Message(channel_id=1, log_time=1, data=state, publish_time=1,
                                              sequence=1))),
           ("a JSON list body", raw("list.mcap", schema, Channel(id=1, topic="sctd/edan/state",
                                                                 message_encoding="json", metadata={},
                                                                 schema_id=1),
                                    Message(channel_id=1, log_time=1, data=b"[1, 2]", publish_time=1,
                                            sequence=1))),
           ("a 10 kB zstd bomb (300 MB)", raw("bomb.mcap", Chunk(
               compression="zstd", data=zstandard.ZstdCompressor(level=19).compress(b"\0" * (300 << 20)),
               message_end_time=0, message_start_time=0, uncompressed_crc=0, uncompressed_size=1000)))]
    seed = bytearray(_log_seed())
    for k in range(40):  # single-bit flips spread over the file
        flipped = bytearray(seed)
        flipped[(k * 7919) % len(flipped)] ^= 1 << (k % 8)
        p = d / f"flip{k}.mcap"
        p.write_bytes(bytes(flipped))
        out.append((f"bit flip {k}", str(p)))
    return out


def _flips_changed(logs: Path) -> int:
    """Bit-flipped logs that read without an error but give other messages than the
    file they were flipped from (0: a flip is refused or changes nothing)."""
    from sctd.bench.fuzz import _log_seed
    from sctd.cli.log import LogError, read_log

    seed = logs / "seed.mcap"
    seed.write_bytes(_log_seed())
    good = read_log(seed)
    changed = 0
    for p in sorted(logs.glob("flip*.mcap")):
        try:
            changed += read_log(p) != good
        except LogError:
            pass
    return changed


def files_phase(d: Path) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, list[dict[str, Any]]] = {"maps": [], "skills": [], "logs": []}
    for sub in ("maps", "skills", "logs"):
        (d / sub).mkdir()
    for what, path in map_files(d / "maps"):
        out["maps"].append({"what": what, **run_command(["input", "keyboard", "--map", path])})
    for what, path in skill_folders(d / "skills", find_skill(defaults().learned_skill)):
        for cmd in ("inspect", "swap"):
            out["skills"].append({"what": f"{what} ({cmd})", **run_command([cmd, path, "--timeout", "2"]
                                                                          if cmd == "swap" else [cmd, path])})
    port = free_port()  # nobody listens: a replay that starts publishes to no one
    for what, path in log_files(d / "logs"):
        r = run_command(["replay", path, "--all", "--speed", "1000", "--connect", f"tcp/127.0.0.1:{port}"],
                        timeout=30)
        out["logs"].append({"what": what, **r})
    return out


# --- the learner ---------------------------------------------------------------------


BAD_REQUESTS: list[tuple[str, dict[str, Any]]] = [
    ("vf_spacing -1", {"params": {"vf_spacing": -1}}), ("vf_spacing 0", {"params": {"vf_spacing": 0}}),
    ("vf_spacing 1e-7", {"params": {"vf_spacing": 1e-7}}), ("n_fields 1e7", {"params": {"n_fields": 10**7}}),
    ("max_n 1e9 (linear)", {"method": "linear", "params": {"max_n": 10**9}}),
    ("min_inliers -1", {"params": {"min_inliers": -1}}),
    ("radius 0 (linear)", {"method": "linear", "params": {"radius": 0}}),
    ("em_iterations 1e9", {"params": {"em_iterations": 10**9}}),
    ("smooth 1e9", {"params": {"smooth": 10**9}}),
    ("n_fields true", {"params": {"n_fields": True}}),
    ("alpha 'abc' (linear)", {"method": "linear", "params": {"alpha": "abc"}}),
    ("gate false", {"gate": False}), ("task '..'", {"task": ".."}), ("demos ['.']", {"demos": ["."]}),
    ("name with NUL", {"name": "a\x00b"}),
]


def _demo(task: str, name: str, obj: str, rows: int) -> bytes:
    return codec.encode_demo(task, name, obj, [[0.01 * k, 0.3, 0.0, 0.05, 0, 0, 0, 1] for k in range(rows)])


def attack_phase(d: Path, seconds: float, logdir: Path) -> dict[str, Any]:
    """The daemon, simulator and learner running; a quiet window, then the hostile files
    to the tools (:func:`files_phase`), then the learner attacked; the daemon's lateness
    over each."""
    keys = Keys()
    found, skill = find_task(defaults().task), defaults().skill  # the bench's task, resolved once
    task = found.name
    hub = f"tcp/127.0.0.1:{free_port()}"
    store = d / "store"
    status: list[dict] = []
    events: list[dict] = []  # the learner's status
    lock = threading.Lock()

    def on_status(sample: Any) -> None:
        with lock:
            status.append(msgpack.unpackb(sample.payload.to_bytes(), raw=False))

    with session(listen=[hub]) as s, \
            Child("sctd.cli.main", "sim", "--task", task, "--connect", hub, "--listen",
                  f"tcp/127.0.0.1:{free_port()}", log=logdir / "sim.log"), \
            Child("sctd.cli.main", "run", "--skill", skill, "--connect", hub, "--listen",
                  f"tcp/127.0.0.1:{free_port()}", log=logdir / "daemon.log"), \
            Child("sctd.cli.main", "learner", "--store", str(store), "--connect", hub, "--listen",
                  f"tcp/127.0.0.1:{free_port()}", log=logdir / "learner.log"), \
            s.declare_subscriber(keys.status, on_status), \
            s.declare_subscriber(keys.learner_status, lambda sample: events.append(
                msgpack.unpackb(sample.payload.to_bytes(), raw=False))):
        end = time.monotonic() + 60
        while not any(e.get("event") == "state" for e in events) or not status:
            if time.monotonic() > end:
                raise RuntimeError(f"the learner or daemon did not come up; see {logdir}")
            time.sleep(0.1)
        time.sleep(2.0)  # past the start-up's first seconds
        quiet = _lateness(status, lock, seconds)
        k0 = len(status)
        files = files_phase(d)
        files_changed = _flips_changed(d / "logs")
        tools = _windows(status, lock, k0)
        k0 = len(status)
        replies = _bad_requests(s, keys, task)
        _bad_demos(s, keys, events, found)
        attacked = _windows(status, lock, k0)
    stored = sum(1 for e in events if e.get("event") == "stored")
    rejected = [e for e in events if e.get("event") == "rejected"]
    return {"files": files, "flips_changed": files_changed, "lateness_tools": tools,
            "requests": replies, "demos_stored": stored,
            "demos_rejected": {r: sum(1 for e in rejected if e.get("reason") == r)
                               for r in sorted({str(e.get("reason")) for e in rejected})},
            "quota_stored": len(list((store / "demos" / "quota").glob("*.csv"))),
            "lateness_quiet": quiet, "lateness_attacked": attacked}


def _bad_requests(s: zenoh.Session, keys: Keys, task: str) -> list[dict[str, Any]]:
    """Each of :data:`BAD_REQUESTS` asked of the learner (to train on ``task``): whether
    it was refused, and what it said."""
    replies = []
    for what, over in BAD_REQUESTS:
        req = {"task": task, "method": "vf", **over}
        got = list(s.get(keys.learner, payload=msgpack.packb(req), timeout=30.0))
        answer = (got[0].err or got[0].ok) if got else None
        body = msgpack.unpackb(answer.payload.to_bytes(), raw=False) if answer is not None else {}
        replies.append({"what": what, "refused": bool(got) and got[0].err is not None,
                        "said": str(body.get("error", body.get("reason", "")))[:160]})
    return replies


def _bad_demos(s: zenoh.Session, keys: Keys, events: list[dict], found: Task) -> None:
    """Demonstrations of ``task`` the learner must refuse (too long, names that are
    paths) and more than a task's quota (of a task ``quota``); returns once the
    learner's status ``events`` account for each of them, or after 120 s."""
    task, obj = found.name, found.object
    for name, rows in (("long", 100_001), ("..", 12), (".h", 12), ("a\x00b", 12)):
        s.put(keys.demos(task, name.replace("\x00", "_")), _demo(task, name, obj, rows), encoding=MSGPACK)
    for k in range(1200):  # distinct names, small: past the task's quota of 1,000
        s.put(keys.demos("quota", f"d{k:04d}"), _demo("quota", f"d{k:04d}", obj, 10), encoding=MSGPACK)
    sent = 1200 + 4

    def handled() -> int:
        return sum(1 for e in list(events) if e.get("event") in ("stored", "rejected", "duplicate"))

    end = time.monotonic() + 120
    while handled() < sent and time.monotonic() < end:
        time.sleep(0.2)


def _lateness(status: list[dict], lock: threading.Lock, seconds: float) -> dict[str, float]:
    """The daemon's worst one-second lateness window over the next ``seconds``."""
    with lock:
        k0 = len(status)
    time.sleep(seconds)
    return _windows(status, lock, k0, settle=0.0)


def _windows(status: list[dict], lock: threading.Lock, k0: int, settle: float = 1.2) -> dict[str, float]:
    """The worst one-second lateness window the daemon reported from status ``k0`` on
    (after ``settle`` s, so that the last second's window is in)."""
    time.sleep(settle)
    with lock:
        reports = [m["recent_ms"]["lateness"] for m in status[k0:] if m.get("recent_ms")]
    # every status report (10 a second) repeats the newest whole window's summary
    windows = [w for k, w in enumerate(reports) if k == 0 or w != reports[k - 1]]
    return {"p99_ms": max((w["p99"] for w in windows), default=0.0),
            "max_ms": max((w["max"] for w in windows), default=0.0), "windows": len(windows)}


# --- the report ----------------------------------------------------------------------


def run_hostile(seconds: float, logdir: Path) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="sctd-hostile-") as tmp:
        d = Path(tmp)
        lr = attack_phase(d, seconds, logdir)
    out: dict[str, Any] = {"files": lr.pop("files"), "flips_changed": lr.pop("flips_changed"), "learner": lr}
    files = [r for rows in out["files"].values() for r in rows]
    flips = [r for r in out["files"]["logs"] if r["what"].startswith("bit flip")]
    out["criteria"] = {
        "every hostile file refused with exit 2, no traceback":
            all(r["exit"] == 2 and not r["traceback"] for r in files if not r["what"].startswith("bit flip")),
        "a bit flip is refused (exit 2) or replays exactly what was logged":
            all(r["exit"] in (0, 2) and not r["traceback"] for r in flips) and out["flips_changed"] == 0,
        "no refusal quotes the file's content": not any(r["quotes_content"] for r in files),
        f"no command above {MAX_RSS_MB:g} MB": max(r["rss_mb"] for r in files) <= MAX_RSS_MB,
        "every bad request refused naming its field": all(r["refused"] for r in lr["requests"]),
        "no demonstration over 100,000 rows, misnamed or past the quota stored":
            lr["quota_stored"] <= 1000 and lr["demos_stored"] <= 1000,
        "daemon lateness p99 while the learner is attacked within 0.1 ms of quiet":
            lr["lateness_attacked"]["p99_ms"] <= lr["lateness_quiet"]["p99_ms"] + 0.1,
    }
    return out


def print_report(r: dict[str, Any]) -> None:
    print("sctd bench hostile: hostile files to the commands that read them; hostile requests and "
          "demonstrations to the learner next to the daemon")
    for kind, rows in r["files"].items():
        print(f"  {kind}:")
        for row in rows:
            if row["what"].startswith("bit flip") and row["exit"] == 2:
                continue
            print(f"    {row['what']:45s} exit {row['exit']}, {row['rss_mb']:6.1f} MB, "
                  f"{row['seconds']:5.2f} s: {row['said']}")
        flips = [x for x in rows if x["what"].startswith("bit flip")]
        if flips:
            print(f"    bit flips: {sum(x['exit'] == 2 for x in flips)} of {len(flips)} refused; of the "
                  f"rest, {r['flips_changed']} read other messages than were logged")
    lr = r["learner"]
    print("  learner requests:")
    for row in lr["requests"]:
        print(f"    {row['what']:22s} {'refused' if row['refused'] else 'ACCEPTED'}: {row['said']}")
    print(f"  demonstrations: stored {lr['demos_stored']}, rejected {lr['demos_rejected']}; "
          f"task 'quota' holds {lr['quota_stored']} of 1,200 sent")
    q, t, a = lr["lateness_quiet"], lr["lateness_tools"], lr["lateness_attacked"]
    print(f"  daemon lateness, worst 1 s window: quiet p99 {q['p99_ms']} ms (max {q['max_ms']}); "
          f"while the tools read the files p99 {t['p99_ms']} ms (max {t['max_ms']}, {t['windows']} s: "
          f"{len(r['files']['maps']) + len(r['files']['skills']) + len(r['files']['logs'])} sctd "
          f"processes on a 2-core host); learner attacked p99 {a['p99_ms']} ms (max {a['max_ms']})")
    mark = {True: "met", False: "NOT met"}
    for k, v in r["criteria"].items():
        print(f"  {k}: {mark[v]}")


def add_hostile_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seconds", type=float, default=5.0, help="quiet and attacked windows, s")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def main_hostile(args: argparse.Namespace) -> int:
    return run_and_report("hostile", args, lambda logdir: run_hostile(args.seconds, logdir), print_report)


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "measure":
        sys.exit(measure_main(sys.argv[2:]))
    print("usage: python -m sctd.bench.hostile measure FILE SCTD-ARGS...", file=sys.stderr)
    sys.exit(2)
