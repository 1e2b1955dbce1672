"""Run a command and say which kinds of process its CPU went to.

Samples ``/proc`` every ``--every`` seconds while the command runs and credits each
process's CPU time (user + system) since the last sample to a label made from its command
line: ``sctd run``, ``sctd sim`` and the other ``sctd`` commands with their first
argument, ``-m module`` for ``python -m``, ``-c`` for ``python -c`` (spawned
multiprocessing workers), ``pytest-worker`` for pytest-xdist's workers, ``chromium``.
Processes that existed before the command count from the first sample; a process that
lives less than one period, or the CPU a process spends after the last sample before it
ends, is missed, so the total is a little under the command's own (``time``).

Usage: ``python tools/cpu_by_process.py [--every S] [--json FILE] -- COMMAND ...``, e.g.
``python tools/cpu_by_process.py -- make test-all`` (docs/testing.md, "Where the suite's
CPU goes"). Prints (on standard error) one line per label, most CPU first; exits with the command's code.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

TICKS = os.sysconf("SC_CLK_TCK")
WORKER = "import sys;exec(eval(sys.stdin.readline()))"  # how execnet starts an xdist worker


def label(argv: list[str]) -> str:
    """The kind of process ``argv`` (its command line) is."""
    line = " ".join(argv)
    if "chrom" in line:
        return "chromium"
    if WORKER in line:
        return "pytest-worker"
    for i, a in enumerate(argv):
        if a == "-m" and i + 1 < len(argv):
            if argv[i + 1] == "sctd.cli.main":
                return " ".join(["sctd", *argv[i + 2:i + 3]])
            return "-m " + argv[i + 1]
        if Path(a).name == "sctd":
            return " ".join(["sctd", *argv[i + 1:i + 2]])
        if a == "-c":
            code = " ".join(argv[i + 1].split(";")[0].split()) if i + 1 < len(argv) else ""
            return f"-c ({code[:30]})"
    return Path(argv[0]).name if argv else "(kernel)"


def snapshot() -> dict[tuple[str, str], tuple[float, str]]:
    """Every process now: (pid, start time) -> (CPU seconds so far, label)."""
    out = {}
    me = str(os.getpid())
    for pid in os.listdir("/proc"):
        if not pid.isdigit() or pid == me:
            continue
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
        except OSError:  # it ended between listdir and reading
            continue
        cpu = (int(fields[11]) + int(fields[12])) / TICKS
        out[(pid, fields[19])] = (cpu, label([a for a in argv if a]))
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--every", type=float, default=0.5, help="seconds between samples (default 0.5)")
    p.add_argument("--json", type=Path, help="also write the figures here")
    p.add_argument("command", nargs=argparse.REMAINDER, help="-- then the command to run")
    args = p.parse_args()
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        p.error("no command given (put it after --)")
    seen = {k: cpu for k, (cpu, _) in snapshot().items()}
    cpu: Counter[str] = Counter()
    started = time.monotonic()
    proc = subprocess.Popen(command)
    while True:
        done = proc.poll() is not None
        for key, (now, name) in snapshot().items():
            cpu[name] += now - seen.get(key, 0.0)
            seen[key] = now
        if done:
            break
        time.sleep(args.every)
    wall = time.monotonic() - started
    total = sum(cpu.values())
    print(f"{wall:.0f} s wall, {total:.0f} CPU-s sampled (this sampler's own left out)", file=sys.stderr)
    for name, s in cpu.most_common():
        if s >= 0.05:
            print(f"{s:8.1f} CPU-s {100 * s / max(total, 1e-9):5.1f} %  {name}", file=sys.stderr)
    if args.json:
        args.json.write_text(json.dumps({"wall_s": round(wall, 1), "cpu_s": {k: round(v, 1) for k, v in
                                                                             cpu.most_common()}}))
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main())
