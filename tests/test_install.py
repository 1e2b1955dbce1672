"""An installed sctd: the wheel built from the repository, installed into a fresh
virtual environment outside the checkout, runs its shipped skills by name from an empty
folder (``sctd run --skill pour.yaml``, ``sctd skills``, ``sctd inspect pour``), and an
unknown name exits 2 naming the places searched. What the commands read besides code
came with the wheel: ``sctd certs`` renders its Zenoh templates, ``sctd bench fuzz``
seeds its corpus from the shipped skills and input maps.

The fresh environment gets the wheel alone (``--no-deps``); its dependencies come from
this test's environment, whose site-packages is put on its path with that folder's
``.pth`` hooks except the checkout's editable install, which is not seen there. The
installed commands run without ``PYTHONPATH``: a checkout on it would stand in for the
wheel.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

import pytest
import zenoh

from sctd.cli.certs import ROLES, ROUTER
from sctd.wire import Keys, codec
from sctd.wire.session import close_session, open_session
from tests.conftest import ROOT, free_port, wait_for
from tests.tiers import needs

pytestmark = pytest.mark.slow  # builds the wheel and installs it in a fresh virtualenv

IGNORE = shutil.ignore_patterns(".venv", ".git", "build", "*.egg-info", "__pycache__", ".pytest_cache",
                                ".mypy_cache", ".ruff_cache", ".hypothesis", "out")


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """The ``bin`` folder of a fresh virtual environment with the built wheel installed."""
    tmp = tmp_path_factory.mktemp("install")
    src = tmp / "src"
    shutil.copytree(ROOT, src, ignore=IGNORE)  # the build writes build/ next to its sources
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                    "-w", str(tmp / "dist"), str(src)], check=True, capture_output=True, timeout=300)
    (wheel,) = (tmp / "dist").glob("sctd-*.whl")
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install",
                    "--no-deps", "--no-index", "-q", str(wheel)], check=True, capture_output=True,
                   timeout=300)
    fresh_site = Path(subprocess.run(
        [str(venv / "bin" / "python"), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True, capture_output=True, text=True).stdout.strip())
    # only after the install: pip would otherwise see (and replace) this environment's sctd
    (fresh_site / "deps.pth").write_text(_deps_pth())
    shutil.rmtree(src)
    return venv / "bin"


def _deps_pth() -> str:
    """A ``.pth`` giving the fresh environment this one's site-packages, with the hooks
    of that folder's own ``.pth`` files (Pinocchio's wheels add their prefix through
    one) except the checkout's editable install."""
    site = Path(sysconfig.get_paths()["purelib"])
    hooks = [line for pth in sorted(site.glob("*.pth")) if not pth.name.startswith("__editable__")
             for line in pth.read_text().splitlines() if line.startswith("import ")]
    return "\n".join([str(site), *hooks]) + "\n"


def _installed_env() -> dict[str, str]:
    """This environment without ``PYTHONPATH``, so that an installed command imports the
    installed sctd (and its children too), not a checkout."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}


def _run(bin_dir: Path, cwd: Path, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(bin_dir / "sctd"), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env=_installed_env())


def test_sctd_comes_from_the_fresh_environment(installed, tmp_path):
    out = subprocess.run([str(installed / "python"), "-c",
                          "import sctd, sctd_sim, sctd_skills; "
                          "print(sctd.__file__); print(sctd_sim.__file__); print(sctd_skills.__file__)"],
                         cwd=tmp_path, check=True, capture_output=True, text=True).stdout.split()
    venv = installed.parent.resolve()
    for path in out:
        assert Path(path).resolve().is_relative_to(venv), (path, venv)
        assert not Path(path).resolve().is_relative_to(ROOT)
    r = _run(installed, tmp_path, "--version")
    assert r.returncode == 0 and r.stdout.startswith("sctd "), r


def test_shipped_skills_resolve_by_name_from_an_empty_folder(installed, tmp_path):
    r = _run(installed, tmp_path, "skills", "--json")
    assert r.returncode == 0, r.stderr
    rows = {row["name"]: row for row in json.loads(r.stdout)}
    assert {"pour", "pour-vf", "drawer", "drawer-vf", "pour-linear", "teleop"} <= set(rows)
    assert rows["pour-vf"]["method"] == "vector_field" and rows["pour"]["object"] == "mug"
    assert all(row["source"] == "shipped" and "error" not in row for row in rows.values())
    for name in ("pour", "pour.yaml", "skills/pour.yaml"):
        r = _run(installed, tmp_path, "inspect", name, "--json")
        assert r.returncode == 0, (name, r.stderr)
        assert json.loads(r.stdout)["id"] == rows["pour"]["id"]
    r = _run(installed, tmp_path, "inspect", "pour-vf", "--json")  # its model file came too
    assert r.returncode == 0 and json.loads(r.stdout)["fields"], r.stderr
    # the shipped skill set and its skills load (the flags are checked after them)
    r = _run(installed, tmp_path, "run", "--set", "kitchen", "--rate", "0")
    assert r.returncode == 2 and r.stderr.strip().endswith("sctd run: --rate: must be > 0"), r.stderr


def test_an_unknown_skill_exits_2_with_the_places_searched(installed, tmp_path):
    for argv in (("inspect", "pur"), ("run", "--skill", "pur")):
        r = _run(installed, tmp_path, *argv)
        assert r.returncode == 2, r
        line = r.stderr.strip().splitlines()[-1]
        assert f"not a file ({tmp_path / 'pur'})" in line, line
        assert "nor a shipped skill in" in line and "did you mean pour" in line, line


def test_installed_daemon_runs_a_shipped_skill_by_name(installed, tmp_path):
    """From an empty folder: the daemon starts on the shipped pour skill, reports
    ``waiting`` (no robot, so no target) and exits 0 on SIGTERM."""
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    p = subprocess.Popen([str(installed / "sctd"), "run", "--skill", "pour.yaml", "--listen", ep,
                          "--connect", ep, "--rt-priority", "0"], cwd=tmp_path, env=_installed_env(),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    session = None
    try:
        session = open_session(connect=[ep])
        seen: list[dict] = []
        sub = session.declare_subscriber(Keys("edan").status,
                                         lambda s: seen.append(codec.unpack_map(s.payload.to_bytes())))
        assert wait_for(lambda: seen, timeout=60.0), "no status from the installed daemon"
        status = seen[-1]
        assert status["skill_name"] == "pour" and status["mode"] == "waiting", status
        assert status["targets"] == 0
        sub.undeclare()
        time.sleep(0.2)
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=30)
        assert p.returncode == 0, err
    finally:
        if session is not None:
            close_session(session)
        if p.poll() is None:
            p.kill()
            p.communicate()


def test_installed_certs_writes_a_working_set_from_an_empty_folder(installed, tmp_path):
    """``sctd certs`` renders the Zenoh templates it installed with (package data, not a
    checkout's deploy folder): every key pair, every role's config, and a router config
    Zenoh parses, listening where ``--router`` says with the certificates written."""
    empty, out = tmp_path / "empty", tmp_path / "tls"
    empty.mkdir()
    r = _run(installed, empty, "certs", "--out", str(out), "--router", "tls/127.0.0.1:7448")
    assert r.returncode == 0, r.stderr
    for role in (ROUTER, *ROLES):
        assert (out / f"{role}.pem").is_file() and (out / f"{role}-key.pem").is_file(), role
    assert (out / "ca.pem").is_file()
    for name in ROLES:
        conf = zenoh.Config.from_file(str(out / "zenoh" / f"{name}.json5"))
        assert json.loads(conf.get_json("connect/endpoints")) == ["tls/127.0.0.1:7448"], name
    router = zenoh.Config.from_file(str(out / "zenoh" / "router.json5"))
    assert json.loads(router.get_json("listen/endpoints")) == ["tls/127.0.0.1:7448"]
    for field, path in (("root_ca_certificate", out / "ca.pem"),
                        ("listen_certificate", out / f"{ROUTER}.pem"),
                        ("listen_private_key", out / f"{ROUTER}-key.pem")):
        assert json.loads(router.get_json(f"transport/link/tls/{field}")) == str(path), field
    assert not any(empty.iterdir())  # it wrote only where it was told


def test_installed_fuzz_bench_runs_seeded_from_the_installed_files(installed, tmp_path):
    """``sctd bench fuzz``, short, on the targets seeded from package data: the file
    reader (the input maps and the shipped skills) and the bundle unpacker (the shipped
    skills). Each seed it wrote is one of those files, and the run reports success."""
    needs("atheris")
    empty, keep = tmp_path / "empty", tmp_path / "corpora"
    empty.mkdir()
    r = _run(installed, empty, "bench", "fuzz", "--target", "yaml", "--target", "bundle",
             "--runs", "300", "--keep", str(keep), "--json", timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    results = {x["target"]: x for x in json.loads(r.stdout)}
    assert set(results) == {"yaml", "bundle"}
    for x in results.values():
        assert x["ok"] and x["runs"] >= 300 and x["coverage"] and not x["crashes"], x
    maps = sorted((ROOT / "services" / "input" / "maps").glob("*.yaml"))
    skills = sorted((ROOT / "skills").glob("*.yaml"))
    assert maps and skills

    def seeds(target: str) -> list[bytes]:
        return sorted(p.read_bytes() for p in (keep / target).glob("seed*"))

    assert seeds("yaml") == sorted(p.read_bytes() for p in maps + skills)
    assert len(seeds("bundle")) == len(skills)
