"""The ``sctd`` command line: every command and flag is there, only the chosen command's
module is imported (``sctd run`` never loads scikit-learn), errors read
``sctd <command>: <problem>`` and bad arguments or input exit 2."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from sctd.cli.main import BENCHES, COMMANDS, build_parser
from tests.conftest import ROOT

HEAVY = ("sklearn", "maxflow", "matplotlib", "pinocchio", "can", "cantools")


def _sctd(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "sctd.cli.main", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def _modules_after(code: str) -> list[str]:
    """The heavy libraries loaded after running ``code`` in a fresh interpreter."""
    probe = f"{code}\nimport sys, json\nprint(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True,
                         timeout=120, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_builds_its_parser(name):
    cmd = COMMANDS[name]
    if cmd.group:
        for bench in cmd.group:
            p = build_parser([name, bench])
            assert p.prog == "sctd"
    else:
        build_parser([name])


@pytest.mark.slow
def test_help_lists_every_command_and_the_exit_codes():
    r = _sctd("--help")
    assert r.returncode == 0
    for name in COMMANDS:
        assert name in r.stdout
    assert "exit codes: 0 done; 1" in " ".join(r.stdout.split())
    r = _sctd("bench", "--help")
    for name in BENCHES:
        assert name in r.stdout


@pytest.mark.slow
def test_run_inspect_and_swap_never_load_the_learners_or_the_simulator():
    code = ("from sctd.cli.main import build_parser\n"
            "build_parser(['run', '--skill', 'skills/pour.yaml'])\n"
            "import sctd.runtime.daemon, sctd.skill\n"
            "sctd.skill.load_skill('skills/pour-vf.yaml')")
    assert _modules_after(code) == []


@pytest.mark.slow
def test_a_bad_flag_value_exits_2_in_the_common_style():
    r = _sctd("learn", "skills/demos/pour", "--out", "/nonexistent/x.yaml", "--lambda", "x")
    assert r.returncode == 2
    assert "sctd learn: argument --lambda" in r.stderr, r.stderr
    r = _sctd("run", "--skill", "skills/pour.yaml", "--rate", "0")
    assert r.returncode == 2
    assert r.stderr.strip().endswith("sctd run: --rate: must be > 0"), r.stderr


@pytest.mark.slow
def test_a_malformed_skill_exits_2_naming_file_and_field(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text((ROOT / "skills" / "pour.yaml").read_text().replace("max_linear_speed: 0.10",
                                                                        "max_linear_speed: -1"))
    for argv in (("inspect", str(bad)), ("run", "--skill", str(bad)), ("swap", str(bad))):
        r = _sctd(*argv)
        assert r.returncode == 2, (argv, r.stderr)
        line = r.stderr.strip().splitlines()[-1]
        assert line.startswith(f"sctd {argv[0]}: {bad}: "), line
        assert "max_linear_speed" in line, line


@pytest.mark.parametrize(("argv", "missing", "extra"), [
    (["learn", "skills/demos/pour", "--out", "x.yaml"], "maxflow", "learn"),  # on import
    (["sim", "--duration", "1"], "pinocchio", "sim"),  # imported once the service starts
])
@pytest.mark.slow
def test_a_missing_optional_library_names_the_extra(argv, missing, extra):
    code = (f"import sys; sys.modules[{missing!r}] = None\n"  # import of it raises ModuleNotFoundError
            "from sctd.cli.main import main\n"
            f"sys.exit(main({argv!r}))")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().splitlines()[-1] == (
        f"sctd {argv[0]}: needs {missing}, which is not installed: pip install 'sctd[{extra}]'"), r.stderr


def test_stuck_after_takes_zero_for_never_and_refuses_negative():
    import argparse

    from sctd.cli.run import add_run_arguments, runtime_config

    p = argparse.ArgumentParser()
    add_run_arguments(p)
    assert runtime_config(p.parse_args(["--skill", "pour"])).stuck_after == 5.0
    assert runtime_config(p.parse_args(["--skill", "pour", "--stuck-after", "0"])).stuck_after == 0.0
    with pytest.raises(ValueError, match="--stuck-after: must be >= 0"):
        runtime_config(p.parse_args(["--skill", "pour", "--stuck-after", "-1"]))
    with pytest.raises(ValueError, match="--rate: must be > 0"):
        runtime_config(p.parse_args(["--skill", "pour", "--rate", "0"]))
