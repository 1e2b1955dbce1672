"""``sctd certs``: a private CA, one key pair per role and the Zenoh config of each role.

The role is the certificate's common name (the router's access control reads it, see
``sctd/deploy/zenoh/router.json5``). Keys are EC P-256, made by the ``openssl`` command
line (no Python crypto library needed). The configs in ``OUT/zenoh/`` are the templates
of ``sctd/deploy/zenoh/`` (package data of :mod:`sctd.deploy`, installed with the wheel)
with the certificate paths pointing into ``OUT`` and the router's endpoints from
``--router``, so a program is configured by its role's file alone::

    sctd certs --out /etc/sctd/tls --host robot-pc.local --router tls/robot-pc.local:7448
    sctd router --config /etc/sctd/tls/zenoh/router.json5
    sctd run --skill pour --zenoh-config /etc/sctd/tls/zenoh/sctd-runtime.json5
"""

from __future__ import annotations

import ipaddress
import json
import os
import secrets
import shutil
import subprocess
import tempfile
from importlib import resources
from pathlib import Path

import zenoh

from ..app.errors import EXIT_OK, fail

ROLES = ("sctd-runtime", "sctd-robot", "sctd-input", "sctd-recorder", "sctd-learner",
         "sctd-operator", "sctd-observer")
ROUTER = "sctd-router"
TEMPLATES = resources.files("sctd.deploy") / "zenoh"  # sctd/deploy/zenoh/, package data
# What the templates say, replaced when rendering.
TEMPLATE_TLS_DIR = "/etc/sctd/tls/"
TEMPLATE_CONNECT = '["tls/robot-pc.local:7448"]'
TEMPLATE_LISTEN = '["tls/0.0.0.0:7448"]'
DEFAULT_ROUTER = "tls/127.0.0.1:7448"


class OpensslError(Exception):
    """openssl is missing or one of its runs failed (the message has its stderr)."""


def add_certs_arguments(p) -> None:
    p.add_argument("--out", required=True, metavar="DIR",
                   help="directory for ca.pem, <role>.pem, <role>-key.pem and zenoh/<role>.json5")
    p.add_argument("--host", action="append", default=[], metavar="NAME",
                   help="DNS name of the router host for its certificate (repeatable; "
                        "localhost is always included)")
    p.add_argument("--ip", action="append", default=[], metavar="ADDR",
                   help="IP address of the router host for its certificate (repeatable; "
                        "127.0.0.1 is always included)")
    p.add_argument("--router", action="append", default=[], metavar="ENDPOINT",
                   help=f"the router's endpoint, which clients connect to and the router listens "
                        f"on (repeatable; default {DEFAULT_ROUTER})")
    p.add_argument("--router-listen", action="append", default=[], metavar="ENDPOINT",
                   help="what the router listens on when it differs from --router "
                        "(e.g. tls/0.0.0.0:7448; repeatable)")
    p.add_argument("--days", type=int, default=825, help="validity of every certificate (days)")
    p.add_argument("--usrpwd", action="store_true",
                   help="also write zenoh/usrpwd/: user/password authentication (user = role) "
                        "over TLS that checks the router only, and users.txt")
    p.add_argument("--force", action="store_true",
                   help="replace an existing CA (every certificate it signed stops working)")


def main_certs(args) -> int:
    out = Path(args.out).resolve()
    if (out / "ca.pem").exists() and not args.force:
        return fail("certs", f"{out / 'ca.pem'}: a CA exists already; --force replaces it "
                             "(every certificate it signed stops working)")
    if args.days < 1:
        return fail("certs", f"--days: {args.days}: must be at least 1")
    for ip in args.ip:
        try:
            ipaddress.ip_address(ip)
        except ValueError:
            return fail("certs", f"--ip: {ip!r}: not an IP address")
    if not TEMPLATES.is_dir():
        return fail("certs", f"{TEMPLATES}: the config templates are missing (sctd/deploy/zenoh/ "
                             "of a source checkout, the package data of sctd.deploy in a wheel)")
    connect = args.router or [DEFAULT_ROUTER]
    listen = args.router_listen or connect
    try:
        make_certificates(out, args.host, args.ip, args.days)
    except OpensslError as e:
        return fail("certs", str(e))
    except OSError as e:
        return fail("certs", f"{out}: {e}")
    written = render_configs(out, connect, listen)
    if args.usrpwd:
        written += render_usrpwd(out)
    print(f"CA and {len(ROLES) + 1} key pairs in {out}; Zenoh configs: "
          f"{', '.join(str(p) for p in written)}", flush=True)
    return EXIT_OK


def _openssl(*argv: str) -> None:
    exe = shutil.which("openssl")
    if exe is None:
        raise OpensslError("openssl: not found on PATH (install the openssl command line)")
    r = subprocess.run([exe, *argv], capture_output=True, text=True)
    if r.returncode != 0:
        raise OpensslError(f"openssl {argv[0]} failed (exit {r.returncode}): {r.stderr.strip()}")


def make_certificates(out: Path, hosts: list[str], ips: list[str], days: int) -> None:
    """Write ``ca.pem``/``ca-key.pem`` and ``<role>.pem``/``<role>-key.pem`` for the router
    and every role into ``out`` (keys mode 0600)."""
    out.mkdir(parents=True, exist_ok=True)
    ec = ("-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes")
    _openssl("req", "-x509", *ec, "-days", str(days), "-subj", "/CN=sctd-ca",
             "-addext", "basicConstraints=critical,CA:TRUE",
             "-addext", "keyUsage=critical,keyCertSign,cRLSign",
             "-keyout", str(out / "ca-key.pem"), "-out", str(out / "ca.pem"))
    os.chmod(out / "ca-key.pem", 0o600)
    names = ["DNS:localhost", *(f"DNS:{h}" for h in hosts),
             "IP:127.0.0.1", *(f"IP:{ip}" for ip in ips)]
    with tempfile.TemporaryDirectory() as tmp:
        for role in (ROUTER, *ROLES):
            ext = ["basicConstraints=critical,CA:FALSE", "keyUsage=critical,digitalSignature",
                   "extendedKeyUsage=serverAuth,clientAuth" if role == ROUTER
                   else "extendedKeyUsage=clientAuth"]
            if role == ROUTER:
                ext.append("subjectAltName=" + ",".join(dict.fromkeys(names)))
            extfile, csr = Path(tmp) / f"{role}.ext", Path(tmp) / f"{role}.csr"
            extfile.write_text("\n".join(ext) + "\n")
            key = out / f"{role}-key.pem"
            _openssl("req", *ec, "-subj", f"/CN={role}", "-keyout", str(key), "-out", str(csr))
            os.chmod(key, 0o600)
            _openssl("x509", "-req", "-in", str(csr), "-CA", str(out / "ca.pem"),
                     "-CAkey", str(out / "ca-key.pem"), "-CAcreateserial",
                     "-CAserial", str(Path(tmp) / "ca.srl"), "-days", str(days),
                     "-extfile", str(extfile), "-out", str(out / f"{role}.pem"))


def render(template: str, tls_dir: Path, connect: list[str], listen: list[str]) -> str:
    """A ``sctd/deploy/zenoh/`` template with its certificate directory and endpoints
    replaced."""
    for marker in (TEMPLATE_TLS_DIR,):
        if marker not in template:
            raise ValueError(f"template lacks {marker!r}")
    text = template.replace(TEMPLATE_TLS_DIR, f"{tls_dir}/")
    text = text.replace(TEMPLATE_CONNECT, json.dumps(connect))
    return text.replace(TEMPLATE_LISTEN, json.dumps(listen))


def render_configs(out: Path, connect: list[str], listen: list[str]) -> list[Path]:
    """Write ``out/zenoh/router.json5`` and ``out/zenoh/<role>.json5``."""
    zdir = out / "zenoh"
    zdir.mkdir(exist_ok=True)
    written = []
    for name in ("router", *ROLES):
        text = render((TEMPLATES / f"{name}.json5").read_text(), out, connect, listen)
        path = zdir / f"{name}.json5"
        path.write_text(text)
        written.append(path)
    return written


def _private_text(path: Path, text: str) -> None:
    path.touch(mode=0o600)
    os.chmod(path, 0o600)
    path.write_text(text)


def render_usrpwd(out: Path) -> list[Path]:
    """Write ``out/users.txt`` (one random password per role) and ``out/zenoh/usrpwd/``:
    the router and role configs of ``out/zenoh/`` with user/password authentication in
    place of client certificates (TLS still authenticates the router and encrypts).
    The files hold passwords: mode 0600."""
    udir = out / "zenoh" / "usrpwd"
    udir.mkdir(exist_ok=True)
    users = {role: secrets.token_urlsafe(24) for role in ROLES}
    _private_text(out / "users.txt", "".join(f"{u}:{pw}\n" for u, pw in users.items()))
    written = []
    for name in ("router", *ROLES):
        conf = zenoh.Config.from_file(str(out / "zenoh" / f"{name}.json5"))
        conf.insert_json5("transport/link/tls/enable_mtls", "false")
        if name == "router":
            conf.insert_json5("transport/auth/usrpwd/dictionary_file",
                              json.dumps(str(out / "users.txt")))
        else:
            conf.insert_json5("transport/link/tls/connect_certificate", "null")
            conf.insert_json5("transport/link/tls/connect_private_key", "null")
            conf.insert_json5("transport/auth/usrpwd/user", json.dumps(name))
            conf.insert_json5("transport/auth/usrpwd/password", json.dumps(users[name]))
        path = udir / f"{name}.json5"
        _private_text(path, str(conf))
        written.append(path)
    return written
