"""Zenoh configs for the hosts of a cluster: a plain TCP router and its clients (until
the secured ones of ``sctd certs`` are used), TLS clients for the intruders a secured
cluster is tried with, and client certificates signed by a cluster's CA."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

ROUTER_PORT = 7447


def router_config(listen: str, *more: str) -> dict:
    """A Zenoh router listening on ``listen`` (and ``more``), multicast scouting off."""
    return {"mode": "router", "listen": {"endpoints": [listen, *more]},
            "scouting": {"multicast": {"enabled": False}},
            "transport": {"shared_memory": {"enabled": False}}}


def client_config(router: str, timeout_ms: int = -1) -> dict:
    """A Zenoh client of the router at ``router`` that retries forever (also after the
    router restarts), multicast scouting off. ``timeout_ms``: how long opening the
    session waits for the router (-1: until it is there)."""
    retry = {"period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 2}
    return {"mode": "client",
            "connect": {"endpoints": [router], "timeout_ms": timeout_ms, "exit_on_failure": False,
                        "retry": retry},
            "scouting": {"multicast": {"enabled": False}},
            "transport": {"shared_memory": {"enabled": False}}}


def tls_client_config(router: str, ca: Path, cert: Path | None = None,
                      key: Path | None = None, timeout_ms: int = 3000) -> dict:
    """A Zenoh client of the TLS router at ``router`` that trusts ``ca``, presenting the
    certificate ``cert`` (private key ``key``) or, without them, none; opening the session
    gives up waiting after ``timeout_ms`` (a refused client would wait forever)."""
    conf = client_config(router, timeout_ms)
    tls: dict = {"root_ca_certificate": str(ca), "verify_name_on_connect": True}
    if cert is not None and key is not None:
        tls.update(connect_certificate=str(cert), connect_private_key=str(key), enable_mtls=True)
    conf["transport"]["link"] = {"protocols": ["tls"], "tls": tls}
    return conf


def sign_certificate(ca_dir: Path, name: str, out: Path) -> tuple[Path, Path]:
    """A client certificate with common name ``name`` signed by the CA in ``ca_dir``
    (``ca.pem``, ``ca-key.pem``), EC P-256, made with the openssl command line; the
    (certificate, key) paths in ``out``."""
    if shutil.which("openssl") is None:
        raise RuntimeError("openssl: not found on PATH")
    out.mkdir(parents=True, exist_ok=True)
    cert, key, csr, ext = (out / f"{name}.pem", out / f"{name}-key.pem", out / f"{name}.csr",
                           out / f"{name}.ext")
    ext.write_text("basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\n"
                   "extendedKeyUsage=clientAuth\n")
    for argv in (["req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
                  "-subj", f"/CN={name}", "-keyout", str(key), "-out", str(csr)],
                 ["x509", "-req", "-in", str(csr), "-CA", str(ca_dir / "ca.pem"), "-CAkey",
                  str(ca_dir / "ca-key.pem"), "-CAcreateserial", "-CAserial", str(out / "ca.srl"),
                  "-days", "30", "-extfile", str(ext), "-out", str(cert)]):
        r = subprocess.run(["openssl", *argv], capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"openssl {argv[0]}: {r.stderr.strip()}")
    return cert, key


def write_config(path: Path, conf: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(conf, indent=2))
    return path
