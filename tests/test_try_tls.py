"""Serving sctd try's and sctd study run's page off this machine's loopback needs mutual
TLS with the certificates of ``sctd certs``; with them, the browser's client certificate's
role decides what its page may do (services/tryout/server.py)."""

from __future__ import annotations

import re

import pytest

from sctd.cli.main import main
from sctd.wire.session import is_loopback
from sctd_services.study.plan import Condition, make_plan, plan_to_yaml
from sctd_services.tryout.server import PageTLSError, page_tls
from tests.browser import open_page
from tests.conftest import run_sctd, sctd, wait_for


def test_loopback_addresses():
    assert all(map(is_loopback, ("127.0.0.1", "127.5.0.1", "::1", "localhost")))
    assert not any(map(is_loopback, ("0.0.0.0", "10.8.0.1", "::", "robot-pc.local")))


@pytest.mark.parametrize("host", ["0.0.0.0", "10.8.0.1", "robot-pc.local"])
def test_sctd_try_refuses_to_serve_off_loopback_without_tls(host, capsys):
    assert main(["try", "--no-view", "--page-host", host]) == 2
    err = capsys.readouterr().err
    assert f"sctd try: --page-host {host}: serving the page off this machine needs --page-tls DIR" in err


def test_a_tls_folder_without_the_files_is_named(tmp_path, capsys):
    with pytest.raises(PageTLSError, match=r"sctd-router\.pem: no such file"):
        page_tls(tmp_path)
    assert main(["try", "--no-view", "--page-tls", str(tmp_path)]) == 2
    assert "sctd try: --page-tls: " in capsys.readouterr().err


def test_sctd_study_run_refuses_before_it_makes_anything(tmp_path, capsys):
    plan = tmp_path / "plan.yaml"
    plan.write_text(plan_to_yaml(make_plan([Condition("drawer-vf", "skill"), Condition("teleop", "teleop")],
                                           ["drawer"], participants=2, practice=1, trials=1)))
    out = tmp_path / "study"
    assert main(["study", "run", "--plan", str(plan), "--out", str(out), "--participant", "P01",
                 "--page-host", "10.8.0.1"]) == 2
    err = capsys.readouterr().err
    assert "--page-host 10.8.0.1: serving the page off this machine needs --page-tls" in err
    assert not out.exists()


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tls")
    done = run_sctd("certs", "--out", str(folder))
    assert done.returncode == 0, done.stderr
    return folder


@pytest.fixture(scope="module")
def served(certs, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("try-tls")
    proc = sctd("try", "--no-view", "--page-tls", str(certs), "--out", str(tmp / "out"), log=tmp / "try.log")
    try:
        line = wait_for(lambda: re.search(r"open (https://127\.0\.0\.1:\d+/) \(Zenoh", proc.output()), 60.0)
        assert line, proc.output()
        yield line.group(1)
    finally:
        assert proc.stop() == 0, proc.output()


def _role_of_page(url: str, certs, role: str | None) -> str | None:
    """Open the page with the client certificate of ``role`` (None: none); the role the
    page was given, ``closed`` when its socket was closed, or None when no page loaded."""
    client = [] if role is None else [{"origin": url.rstrip("/"), "certPath": str(certs / f"{role}.pem"),
                                       "keyPath": str(certs / f"{role}-key.pem")}]
    with open_page(url, client_certificates=client, load=False) as bp:
        try:
            bp.page.goto(url, timeout=20_000)
        except Exception:  # the handshake refused: no page at all
            return None
        closed = "window.sctdSocket && window.sctdSocket.readyState === 3"
        role = "window.sctdState && window.sctdState.role"
        got = bp.page.wait_for_function(f"({closed}) ? 'closed' : ({role})", timeout=20_000)
        return got.json_value()


@pytest.mark.slow
@pytest.mark.parametrize(("role", "expected"), [("sctd-input", "controller"), ("sctd-observer", "watcher"),
                                               ("sctd-robot", "closed")])
def test_the_client_certificates_role_decides_what_the_page_may_do(certs, served, role, expected):
    assert _role_of_page(served, certs, role) == expected


@pytest.mark.slow
def test_no_client_certificate_no_page(certs, served):
    assert _role_of_page(served, certs, None) is None
