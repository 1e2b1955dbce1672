"""The test tiers, enforced (a pytest plugin, loaded by ``tests/conftest.py``).

- ``slow``: the test starts processes or network namespaces, runs in real time, installs
  or fuzzes. ``make test`` leaves these out; ``make test-all`` runs everything.
- ``realtime``: a slow test whose verdict depends on the machine keeping time (tick
  lateness, rates measured against a live daemon). ``make test-all`` runs the slow tier
  one test at a time, so these never run beside another test.

A test not marked ``slow`` that starts a process (``subprocess``, ``multiprocessing``,
``os.fork``, ``os.posix_spawn``, a pty) fails at the call that starts it, with the call
named, whether the test itself or one of its fixtures makes it. A network namespace is
made by a process (``ip netns``), so it is caught the same way.
"""

from __future__ import annotations

import importlib
import json
import os
import re
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

MARKERS = {
    "slow": "starts processes or namespaces, runs in real time, installs or fuzzes "
            "(left out of `make test`)",
    "realtime": "a slow test whose verdict needs the machine to keep time: run alone, "
                "never beside another test",
}


# The import names that each optional extra of pyproject.toml installs (tests/test_tiers.py
# checks that every extra is here).
EXTRAS = {
    "learn": ("sklearn", "maxflow", "matplotlib"),
    "sim": ("pinocchio", "can", "cantools"),
    "dev": ("pytest", "hypothesis", "atheris", "gco", "importlinter", "setuptools", "playwright",
            "franky_sim", "mujoco"),
    "view": ("viser",),
    "inputs": ("sdl2", "hid", "brainflow"),
    "logs": ("mcap",),
    "ros": ("rosbags", "xxhash"),
    "ros2": ("rclpy", "std_msgs", "geometry_msgs", "sensor_msgs", "diagnostic_msgs", "visualization_msgs"),
    "cluster": ("dask", "distributed"),
    "franky": ("franky",),
}
_EXTRA_OF = {module: extra for extra, modules in EXTRAS.items() for module in modules}


def missing_extra(exc: BaseException | None) -> str | None:
    """The extra whose module ``exc`` failed to import, if it is one."""
    if isinstance(exc, ModuleNotFoundError) and exc.name:
        return _EXTRA_OF.get(exc.name.split(".")[0])
    return None


def skip_reason(extra: str, exc: BaseException) -> str:
    return f"needs the '{extra}' extra ({exc}): pip install -e '.[{extra}]'"


def needs(module: str) -> Any:
    """``module``, from an optional extra: for an import inside a test. The hooks below
    turn its absence into a skip naming the extra, or a failure under CI."""
    return importlib.import_module(module)


class ProcessInFastTier(BaseException):
    """A BaseException, so that a test's ``except Exception`` cannot swallow it."""


def _describe(args: tuple, kwargs: dict) -> str:
    for a in (*args, *kwargs.values()):
        if isinstance(a, (list, tuple)) and a and isinstance(a[0], (str, bytes, os.PathLike)):
            return " ".join(os.fsdecode(x) if isinstance(x, (bytes, os.PathLike)) else str(x)
                            for x in a[:6])
        if isinstance(a, (str, bytes)):
            return os.fsdecode(a)
    return ""


class _Guard:
    """Wraps the functions through which Python starts processes while a fast test (its
    fixtures included) runs."""

    def __init__(self) -> None:
        self.saved: list[tuple[Any, str, Callable]] = []
        self.started: list[str] = []
        self.reported = False  # a refusal already failed the test's setup or call

    def _targets(self) -> list[tuple[Any, str]]:
        import _posixsubprocess  # multiprocessing's spawn calls it
        import subprocess  # holds its own reference to fork_exec

        out: list[tuple[Any, str]] = [(_posixsubprocess, "fork_exec")]
        if hasattr(subprocess, "_fork_exec"):
            out.append((subprocess, "_fork_exec"))
        for name in ("fork", "forkpty", "posix_spawn", "posix_spawnp", "system"):
            if hasattr(os, name):
                out.append((os, name))
        return out

    def install(self, nodeid: str) -> None:
        for owner, name in self._targets():
            real = getattr(owner, name)
            self.saved.append((owner, name, real))
            setattr(owner, name, self._refuse(nodeid, f"{owner.__name__}.{name}"))

    def _refuse(self, nodeid: str, what: str) -> Callable:
        def refuse(*args: Any, **kwargs: Any) -> Any:
            call = f"{what}({_describe(args, kwargs)})"
            self.started.append(call)
            raise ProcessInFastTier(
                f"{nodeid} is not marked slow but starts a process: {call}. Mark it "
                "@pytest.mark.slow (tests/tiers.py), or test the code in-process.")
        return refuse

    def uninstall(self) -> list[str]:
        for owner, name, real in reversed(self.saved):
            setattr(owner, name, real)
        self.saved.clear()
        started, self.started = self.started, []
        return started


# Seconds each test module took (setup, call and teardown of its tests summed), longest
# first: ``make test-all`` hands whole modules to its workers (``--dist loadscope``), and
# a long module started last keeps one worker busy while the other has nothing left. The
# modules are collected longest first, so the short ones fill in at the end. Recorded by
# a run on workers with ``SCTD_RECORD_MODULE_SECONDS=1`` (``SCTD_RECORD_MODULE_SECONDS=1
# make test-all`` records its first tier); a module missing from it runs after those
# listed, and a stale figure only orders the run less well.
MODULE_SECONDS = Path(__file__).resolve().parent / "data" / "module_seconds.json"


def module_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


def longest_first(items: list[pytest.Item], seconds: dict[str, float]) -> None:
    """Sort ``items`` module by module, the modules by ``seconds`` (longest first, then
    as collected); a module's own tests keep their order."""
    first: dict[str, int] = {}
    for i, item in enumerate(items):
        first.setdefault(module_of(item.nodeid), i)
    items.sort(key=lambda it: (-seconds.get(module_of(it.nodeid), 0.0), first[module_of(it.nodeid)]))


class Tiers:
    def __init__(self) -> None:
        self.guard = _Guard()
        self.seconds: defaultdict[str, float] = defaultdict(float)

    def pytest_collection_modifyitems(self, config: pytest.Config, items: list[pytest.Item]) -> None:
        if MODULE_SECONDS.exists():
            longest_first(items, json.loads(MODULE_SECONDS.read_text()))

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        self.seconds[module_of(report.nodeid)] += report.duration

    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        # Written by the process that saw every report of a run on workers (not a worker),
        # for a run of this repository's suite (not a pytester run inside it).
        config = session.config
        if (os.environ.get("SCTD_RECORD_MODULE_SECONDS") and not hasattr(config, "workerinput")
                and getattr(config.option, "dist", "no") != "no"
                and config.rootpath == MODULE_SECONDS.parents[2] and self.seconds):
            old = json.loads(MODULE_SECONDS.read_text()) if MODULE_SECONDS.exists() else {}
            new = {**old, **{m: round(s, 1) for m, s in self.seconds.items()}}
            MODULE_SECONDS.write_text(json.dumps(dict(sorted(new.items(), key=lambda kv: -kv[1])), indent=0)
                                      + "\n")

    # A test (or a test module) that needs an optional extra which is not installed is
    # skipped with the extra named. Under CI (``CI`` set) every extra is installed, and the
    # import error stays a failure: a broken install must not pass as skips.
    @pytest.hookimpl(hookwrapper=True)
    def pytest_make_collect_report(self, collector: pytest.Collector):
        outcome = yield
        report = outcome.get_result()
        if report.failed and not os.environ.get("CI") and isinstance(collector, pytest.Module):
            # The report keeps the import error as text only.
            found = re.search(
                r"ModuleNotFoundError: (No module named '([\w.]+)'|import of ([\w.]+) halted.*)",
                str(report.longrepr))
            exc = ModuleNotFoundError(found[1], name=found[2] or found[3]) if found else None
            extra = missing_extra(exc)
            if extra is not None and exc is not None:
                report.outcome = "skipped"
                report.longrepr = (str(collector.path), 0, "Skipped: " + skip_reason(extra, exc))

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_makereport(self, item: pytest.Item, call: pytest.CallInfo):
        outcome = yield
        if call.excinfo is not None and call.excinfo.errisinstance(ProcessInFastTier):
            self.guard.reported = True
        if call.excinfo is None or os.environ.get("CI"):
            return
        extra = missing_extra(call.excinfo.value)
        if extra is not None:
            report = outcome.get_result()
            report.outcome = "skipped"
            report.longrepr = (str(item.path), item.location[1] or 0,
                               "Skipped: " + skip_reason(extra, call.excinfo.value))

    @pytest.hookimpl(tryfirst=True)
    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        if item.get_closest_marker("realtime") and not item.get_closest_marker("slow"):
            pytest.fail(f"{item.nodeid}: a realtime test is a slow test; mark it slow too",
                        pytrace=False)
        if not item.get_closest_marker("slow"):
            self.guard.install(item.nodeid)

    @pytest.hookimpl(hookwrapper=True, trylast=True)
    def pytest_runtest_teardown(self, item: pytest.Item, nextitem: pytest.Item | None):
        outcome = yield
        reported, self.guard.reported = self.guard.reported, False
        started = self.guard.uninstall()
        if started and not reported and outcome.excinfo is None:
            # Reported even if the test caught the refusal.
            pytest.fail(f"{item.nodeid} is not marked slow but started: {', '.join(started)}",
                        pytrace=False)


def _warm_caches() -> None:
    """What a library does once per machine by starting a process, done before any test's
    guard is up: matplotlib lists the system's fonts with ``fc-list`` the first time it is
    imported and keeps the list in its cache (on a fresh machine the first fast test to
    import it would otherwise be refused)."""
    try:
        import matplotlib.font_manager  # noqa: F401
    except ImportError:  # (the 'learn' extra is not installed: its tests are skipped)
        pass


def pytest_configure(config: pytest.Config) -> None:
    _warm_caches()
    for name, text in MARKERS.items():
        config.addinivalue_line("markers", f"{name}: {text}")
    if not config.pluginmanager.has_plugin("sctd-tiers"):
        config.pluginmanager.register(Tiers(), "sctd-tiers")

