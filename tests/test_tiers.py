"""The tiers' hook (tests/tiers.py), shown on small test files run by pytester in this
process: a fast test that starts a process fails, naming the call, however it starts it;
a test that needs a missing extra is skipped naming the extra, and fails under CI."""

from __future__ import annotations

import tomllib

import pytest

from tests import tiers
from tests.conftest import ROOT


def _run(pytester: pytest.Pytester, source: str, *args: str) -> pytest.RunResult:
    pytester.makepyfile(test_inner=source)
    return pytester.runpytest_inprocess("-p", "tests.tiers", "-p", "no:cacheprovider", *args)


@pytest.mark.parametrize("start", [
    "subprocess.run(['true'])",
    "os.system('true')",
    "multiprocessing.get_context('spawn').Process(target=print).start()",
    "multiprocessing.get_context('fork').Process(target=print).start()",
    "os.posix_spawnp('true', ['true'], os.environ)",
])
def test_a_fast_test_that_starts_a_process_fails_naming_the_call(pytester, start):
    result = _run(pytester, f"""
import multiprocessing, os, subprocess

def test_starts():
    {start}
""")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*test_starts is not marked slow but start*"])


def test_a_fixture_that_starts_a_process_fails_the_fast_test(pytester):
    result = _run(pytester, """
import subprocess, pytest

@pytest.fixture(scope="module")
def child():
    return subprocess.Popen(["true"])

def test_uses(child):
    pass
""")
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines(["*not marked slow but starts a process: *fork_exec(true)*"])


def test_a_refusal_the_test_catches_still_fails_it(pytester):
    result = _run(pytester, """
import subprocess

def test_hides():
    try:
        subprocess.run(["true"])
    except BaseException:
        pass
""")
    assert result.ret != 0
    result.stdout.fnmatch_lines(["*test_hides is not marked slow but started: *fork_exec(true)*"])


def test_realtime_without_slow_is_refused_and_unknown_markers_too(pytester):
    result = _run(pytester, """
import pytest

@pytest.mark.realtime
def test_clock():
    pass
""")
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines(["*a realtime test is a slow test*"])
    result = _run(pytester, """
import pytest

@pytest.mark.sloww
def test_typo():
    pass
""", "--strict-markers")
    assert result.ret != 0
    result.stdout.fnmatch_lines(["*'sloww' not found in `markers`*"])


@pytest.mark.slow
def test_a_slow_test_may_start_a_process(pytester):
    result = _run(pytester, """
import subprocess, pytest

@pytest.mark.slow
def test_starts():
    assert subprocess.run(["true"]).returncode == 0
""")
    result.assert_outcomes(passed=1)


_NEEDS_MCAP = """
import sys
sys.modules["mcap"] = None  # as if the logs extra were not installed
import mcap.reader

def test_reads():
    pass
"""

_NEEDS_MCAP_INSIDE = """
import sys

def test_reads():
    sys.modules["mcap"] = None
    try:
        import mcap.reader
    finally:
        del sys.modules["mcap"]
"""


@pytest.mark.parametrize("source", [_NEEDS_MCAP, _NEEDS_MCAP_INSIDE], ids=["module", "test"])
def test_a_missing_extra_skips_naming_it_and_fails_under_ci(pytester, monkeypatch, source):
    saved = __import__("sys").modules.get("mcap")
    try:
        monkeypatch.delenv("CI", raising=False)
        result = _run(pytester, source, "-rs")
        result.assert_outcomes(skipped=1)
        result.stdout.fnmatch_lines(["*needs the 'logs' extra*pip install -e '.[[]logs[]]'*"])
        monkeypatch.setenv("CI", "1")
        result = _run(pytester, source)
        assert result.ret != 0
        result.stdout.fnmatch_lines(["*ModuleNotFoundError*mcap*"])
    finally:
        if saved is not None:
            __import__("sys").modules["mcap"] = saved


def test_every_extra_of_the_package_is_known():
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert set(declared) == set(tiers.EXTRAS)


def test_modules_are_collected_longest_first_each_keeping_its_order():
    """``make test-all`` hands modules to its workers in the order collected: the longest
    by ``tests/data/module_seconds.json`` first, one not listed after them."""
    from types import SimpleNamespace

    ids = ["a.py::t1", "a.py::t2", "b.py::t1", "c.py::t1", "c.py::t2", "d.py::t1"]
    items = [SimpleNamespace(nodeid=i) for i in ids]
    tiers.longest_first(items, {"c.py": 30.0, "a.py": 5.0, "d.py": 5.0})  # type: ignore[arg-type]
    assert [i.nodeid for i in items] == ["c.py::t1", "c.py::t2", "a.py::t1", "a.py::t2", "d.py::t1",
                                         "b.py::t1"]
