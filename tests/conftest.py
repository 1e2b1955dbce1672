"""Shared fixtures: free loopback ports, real subprocesses that are always reaped, and
Zenoh sessions on explicit loopback endpoints (multicast scouting off)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import settings

from sctd.cli import procs
from sctd.cli.procs import Child, free_port, port_is_free

pytest_plugins = ["pytester", "tests.tiers"]

# No per-example deadline: the suite runs on loaded machines (CI, two suites at once),
# where a deadline measures the machine, not the code.
settings.register_profile("sctd", deadline=None)
settings.load_profile("sctd")

__all__ = ["ROOT", "Proc", "free_port", "port_is_free", "running_cluster", "sctd", "trap_skill_yaml",
           "wait_for"]

ROOT = Path(__file__).resolve().parents[1]


def _port_slice() -> None:
    """Under pytest-xdist, each worker (and every program it starts) draws its loopback
    ports from a slice of the range of its own: two workers never get the same port."""
    worker, count = os.environ.get("PYTEST_XDIST_WORKER"), os.environ.get("PYTEST_XDIST_WORKER_COUNT")
    if not worker or not count or os.environ.get("SCTD_PORT_RANGE"):
        return
    n, m = int(worker.removeprefix("gw")), int(count)
    bottom, top = procs._port_range()
    size = (top - bottom + 1) // m
    os.environ["SCTD_PORT_RANGE"] = f"{bottom + n * size}-{bottom + (n + 1) * size - 1}"


_port_slice()
_live: list[subprocess.Popen] = []


class Proc(Child):
    """A child that the leak check below knows about."""

    def __init__(self, module: str, *args: str, log: Path):
        super().__init__(module, *args, log=log, cwd=ROOT)
        _live.append(self.p)

    def stop(self, timeout: float = 10.0, sig: int = signal.SIGTERM) -> int:
        rc = super().stop(timeout, sig)
        if self.p in _live:
            _live.remove(self.p)
        return rc


def sctd(*args: str, log: Path) -> Proc:
    return Proc("sctd.cli.main", *args, log=log)


def run_sctd(*args: str, timeout: float = 90.0,
             env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """``sctd ARGS`` run to its end (killed after ``timeout``), output captured; ``env``:
    its environment (default this process's)."""
    return subprocess.run([sys.executable, "-m", "sctd.cli.main", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, env=env)


@pytest.fixture(autouse=True, scope="session")
def private_store(tmp_path_factory):
    """The learner's store (``$SCTD_STORE``, read by every skill lookup) is a folder of
    the test run's own, never the user's; children inherit it."""
    folder = tmp_path_factory.mktemp("store")
    old = os.environ.get("SCTD_STORE")
    os.environ["SCTD_STORE"] = str(folder)
    yield folder
    if old is None:
        os.environ.pop("SCTD_STORE", None)
    else:
        os.environ["SCTD_STORE"] = old


@pytest.fixture(autouse=True, scope="session")
def private_tmp(tmp_path_factory):
    """The programs the tests start keep their temporary files in a folder of the test
    run's own (``$TMPDIR``, which children inherit; pytest keeps its last three runs'
    folders, as it does every ``tmp_path``), never in /tmp: a program a test kills as a
    power cut would (SIGKILL: a daemon's kept bundles, a trial's skill file) leave its
    temporary folder there for good, and Dask leaves its scratch space. This process's
    own temporary files stay where they were (``tempfile`` has read ``$TMPDIR`` by now)."""
    folder = tmp_path_factory.mktemp("tmp")
    old = os.environ.get("TMPDIR")
    os.environ["TMPDIR"] = str(folder)
    yield folder
    if old is None:
        os.environ.pop("TMPDIR", None)
    else:
        os.environ["TMPDIR"] = old


def _reap(since: set[int]) -> list[subprocess.Popen]:
    """Kill the children started after ``since`` (their pids) that still run."""
    leaked = [p for p in _live if p.pid not in since and p.poll() is None]
    for p in leaked:
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()
    _live[:] = [p for p in _live if p.pid in since and p.poll() is None]
    return leaked


@pytest.fixture(autouse=True, scope="module")
def no_processes_left_by_the_module():
    """A module's shared processes (a module-scoped daemon) are stopped by the end of
    the module."""
    yield
    leaked = _reap(set())
    assert not leaked, f"the module left {len(leaked)} process(es) running: {[p.args for p in leaked]}"


@pytest.fixture(autouse=True)
def no_leaked_processes():
    """A test stops what it started (a module's shared processes are not its own)."""
    before = {p.pid for p in _live}
    yield
    leaked = _reap(before)
    assert not leaked, f"test left {len(leaked)} process(es) running: {[p.args for p in leaked]}"


def must_centre(status: dict | None, device: str) -> bool:
    """Whether the daemon's newest status names ``device`` in ``input.rearm``: its push
    moves nothing until it sends a zero. A test's driver centres the stick then, as a
    person reading the display does: on a busy machine a driver's thread can fall silent
    for longer than the daemon lets a push go stale."""
    inp = (status or {}).get("input")
    return isinstance(inp, dict) and device in (inp.get("rearm") or {})


def wait_for(pred, timeout: float = 10.0, interval: float = 0.02):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(interval)
    return pred()


def trap_skill_yaml(enter_x: float) -> str:
    """A skill that traps the user (thesis Ch. 6.2): ``free`` (x, y, z) enters ``slide``
    at ``x > enter_x`` (m, the mug's frame); ``slide`` maps only x, while its way on to
    ``done`` needs z."""
    return f"""
sctd_skill: 1
name: trap
object: mug
limits: {{max_linear_speed: 0.1, max_angular_speed: 0.5}}
fsm:
  start: free
  end: done
  min_dwell: 0.0
  transitions:
    - {{from: free, to: slide, type: hyperplane, normal: [1, 0, 0], offset: {-enter_x}, margin: 0.0}}
    - {{from: slide, to: done, type: hyperplane, normal: [0, 0, 1], offset: -0.5, margin: 0.0}}
states:
  free: {{input_mapping: [{{type: linear, axes: [tx, ty, tz]}}]}}
  slide: {{input_mapping: [{{type: linear, axes: [tx]}}]}}
  done: {{input_mapping: [{{type: linear, axes: [tx, ty, tz]}}]}}
"""


def require_namespaces() -> None:
    """Skip the test, naming why, where network namespaces cannot be made (not root);
    under CI (``$CI`` set), where they must run, fail it instead."""
    from sctd.deploy.netns import can_make_namespaces

    why = can_make_namespaces()
    if why is not None:
        if os.environ.get("CI"):
            pytest.fail(f"network namespaces cannot be made in CI: {why}")
        pytest.skip(f"network namespaces cannot be made here: {why}")


@contextlib.contextmanager
def running_cluster(logdir: Path, **kw) -> Iterator:
    """A ``sctd.deploy.cluster.Cluster`` (``kw``: its arguments) with its router started,
    for a module's tests (skipped where namespaces cannot be made). On the way out the
    router is stopped and its own ending asserted (0: its session closed, 3: Zenoh did
    not close it within 2 s, as it says; never a kill), the hosts are removed and no
    namespace of the run is left."""
    from sctd.app.errors import EXIT_FORCED, EXIT_OK
    from sctd.deploy.cluster import Cluster
    from sctd.deploy.netns import NamespaceError, namespaces

    require_namespaces()
    c = Cluster(logdir, **kw)
    try:
        c.__enter__()
    except NamespaceError as e:
        pytest.fail(f"making the hosts failed: {e}")
    try:
        c.start_router()
        yield c
    finally:
        run_id = c.hosts.run_id
        try:
            router_rc = c.stop_router()
            router_log = "" if c.router is None else c.router.output()[-2000:]
        finally:
            c.__exit__(None, None, None)
        assert namespaces(run_id) == [], f"namespaces left over: {namespaces(run_id)}"
        assert router_rc in (None, EXIT_OK, EXIT_FORCED), (router_rc, router_log)
