"""Every Zenoh config shipped in sctd/deploy/zenoh/ is accepted by Zenoh's own parser, the
loopback file says what the built-in defaults do, and ``sctd certs`` makes the CA, the
role certificates and each role's config (the policy itself: tests/test_acl.py)."""

import json
import subprocess
from importlib import resources
from pathlib import Path

import pytest
import zenoh

from sctd.cli.certs import ROLES, ROUTER
from sctd.cli.main import main
from sctd.wire.session import HUB

DEPLOY = Path(str(resources.files("sctd.deploy"))) / "zenoh"  # what the wheel ships


@pytest.mark.parametrize("path", sorted(DEPLOY.glob("*.json5")), ids=lambda p: p.name)
def test_zenoh_accepts_config(path):
    conf = zenoh.Config.from_file(str(path))
    assert "multicast" in conf.get_json("scouting")
    assert conf.get_json("scouting/multicast/enabled") == "false"


def test_loopback_file_matches_defaults():
    conf = zenoh.Config.from_file(str(DEPLOY / "loopback.json5"))
    assert HUB in conf.get_json("listen/endpoints") and HUB in conf.get_json("connect/endpoints")


def _subject(pem: Path, *ext: str) -> str:
    r = subprocess.run(["openssl", "x509", "-in", str(pem), "-noout", "-subject",
                        *(["-ext", ",".join(ext)] if ext else [])],
                       capture_output=True, text=True, check=True)
    return r.stdout


@pytest.mark.slow
def test_certs_one_key_pair_per_role_signed_by_the_ca(tmp_path, capsys):
    out = tmp_path / "tls"
    assert main(["certs", "--out", str(out), "--host", "robot-pc.local", "--ip", "10.8.0.1",
                 "--router", "tls/10.8.0.1:7448"]) == 0
    assert (out / "ca-key.pem").stat().st_mode & 0o777 == 0o600
    for role in (ROUTER, *ROLES):
        assert f"CN = {role}" in _subject(out / f"{role}.pem")
        assert (out / f"{role}-key.pem").stat().st_mode & 0o777 == 0o600
        subprocess.run(["openssl", "verify", "-CAfile", str(out / "ca.pem"), str(out / f"{role}.pem")],
                       check=True, capture_output=True)
    san = _subject(out / f"{ROUTER}.pem", "subjectAltName")
    for name in ("DNS:localhost", "DNS:robot-pc.local", "IP Address:127.0.0.1",
                 "IP Address:10.8.0.1"):
        assert name in san
    # every rendered config parses and points into the directory and at the router
    for name in ("router", *ROLES):
        conf = zenoh.Config.from_file(str(out / "zenoh" / f"{name}.json5"))
        assert str(out) in conf.get_json("transport/link/tls/root_ca_certificate")
        eps = "listen/endpoints" if name == "router" else "connect/endpoints"
        assert json.loads(conf.get_json(eps)) == ["tls/10.8.0.1:7448"]
    conf = zenoh.Config.from_file(str(out / "zenoh" / "sctd-input.json5"))
    assert conf.get_json("transport/link/tls/connect_certificate") == json.dumps(
        str(out / "sctd-input.pem"))
    # an existing CA is kept unless --force
    ca = (out / "ca.pem").read_text()
    capsys.readouterr()
    assert main(["certs", "--out", str(out)]) == 2
    assert "a CA exists already" in capsys.readouterr().err and (out / "ca.pem").read_text() == ca
    assert main(["certs", "--out", str(out), "--force"]) == 0
    assert (out / "ca.pem").read_text() != ca


@pytest.mark.slow
def test_certs_without_openssl_or_when_it_fails(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PATH", str(tmp_path))
    assert main(["certs", "--out", str(tmp_path / "a")]) == 2
    assert "openssl: not found" in capsys.readouterr().err
    monkeypatch.undo()
    assert main(["certs", "--out", str(tmp_path / "b"), "--host", "bad,name=1"]) == 2
    err = capsys.readouterr().err
    assert "openssl x509 failed" in err and "(exit " in err


def test_router_policy_denies_by_default_on_tls_only():
    conf = zenoh.Config.from_file(str(DEPLOY / "router.json5"))
    assert conf.get_json("access_control/default_permission") == '"deny"'
    assert conf.get_json("access_control/enabled") == "true"
    assert all(ep.startswith("tls/") for ep in json.loads(conf.get_json("listen/endpoints")))
    assert conf.get_json("transport/link/tls/enable_mtls") == "true"
    for role in ROLES:
        client = zenoh.Config.from_file(str(DEPLOY / f"{role}.json5"))
        assert client.get_json("mode") == '"client"'
        assert client.get_json("connect/timeout_ms") == "-1"
        assert client.get_json("connect/exit_on_failure") == "false"
