"""``tools/cpu_by_process.py`` (docs/testing.md, "Where the suite's CPU goes"): what kind
of process each command line is, and a busy child's CPU credited to its label."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

TOOL = Path(__file__).resolve().parents[1] / "tools" / "cpu_by_process.py"


@pytest.fixture(scope="module")
def tool():
    spec = importlib.util.spec_from_file_location("cpu_by_process", TOOL)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(("argv", "want"), [
    (["/v/bin/python", "/v/bin/sctd", "run", "--skill", "pour"], "sctd run"),
    (["/v/bin/python", "-m", "sctd.cli.main", "sim", "--task", "pour"], "sctd sim"),
    (["/v/bin/python", "-m", "sctd_sim.service", "--x"], "-m sctd_sim.service"),
    (["/v/bin/python", "-c", "from multiprocessing.spawn import spawn_main; spawn_main()"],
     "-c (from multiprocessing.spawn imp)"),
    (["/v/bin/python", "-c", "import sys;exec(eval(sys.stdin.readline()))"], "pytest-worker"),
    (["/usr/lib/chromium/chromium", "--type=renderer"], "chromium"),
    (["/usr/bin/make", "test-all"], "make"),
    ([], "(kernel)"),
])
def test_each_command_line_gets_its_kind(tool, argv, want):
    assert tool.label(argv) == want


@pytest.mark.slow
def test_a_busy_child_is_credited_to_its_label_and_the_exit_code_passed_on(tool, tmp_path):
    out = tmp_path / "cpu.json"
    # 1.5 s of CPU, then a rest long enough for a sample to see all of it, even a late one
    busy = ("import time\nt = time.process_time()\nwhile time.process_time() - t < 1.5: pass\n"
            "time.sleep(2)\nraise SystemExit(3)")
    done = subprocess.run([sys.executable, str(TOOL), "--every", "0.1", "--json", str(out), "--",
                           sys.executable, "-c", busy], capture_output=True, text=True, timeout=60)
    assert done.returncode == 3, done.stderr
    cpu = json.loads(out.read_text())["cpu_s"]
    name = tool.label([sys.executable, "-c", busy])
    assert name == "-c (import time t = time.process_t)"
    assert cpu[name] >= 1.45, cpu  # its 1.5 s, to the kernel's clock tick
    assert name in done.stderr
