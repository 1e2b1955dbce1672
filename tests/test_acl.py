"""The router's access control holds on loopback: each role may do exactly what the
roles table (docs/deploy.md) says, and strangers get nothing through.

Certificates come from ``sctd certs`` in tmp_path, the router is ``sctd router --config
DIR/zenoh/router.json5`` on a free TLS port, every session uses its role's rendered
config. A denied flow is checked only after the allowed ones were delivered in full, so
a 0 means denied, not slow.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest
import zenoh

from sctd.app.errors import EXIT_FORCED, EXIT_OK
from sctd.cli.certs import ROLES
from sctd.wire.session import close_session
from tests.conftest import Proc, free_port, sctd, wait_for

pytestmark = pytest.mark.slow  # routers and clients as processes

N = 20
ROBOT = "edan"
# every published key of the wire contract, and the role that owns it
OWNER = {"input/pad": "sctd-input", "state": "sctd-robot", "objects/cup": "sctd-robot",
         "target": "sctd-runtime", "gripper": "sctd-runtime", "status": "sctd-runtime", "scene": "sctd-robot",
         "can": "sctd-robot", "demos/pour/d1": "sctd-recorder",
         "learner/status": "sctd-learner"}
# queryables and the role that answers each
ANSWERS = {"skill": "sctd-runtime", "skill/swap": "sctd-runtime", "skill/bundle": "sctd-runtime",
           "learner": "sctd-learner", "sim/reset": "sctd-robot"}
EVERY = set(OWNER)
# the roles table: what each role may publish, subscribe, answer and query
PUB = {"sctd-runtime": {"target", "gripper", "status"},
       "sctd-robot": {"state", "objects/cup", "scene", "can"},
       "sctd-input": {"input/pad"}, "sctd-recorder": {"demos/pour/d1"},
       "sctd-learner": {"learner/status"}, "sctd-operator": set(), "sctd-observer": set()}
SUB = {"sctd-runtime": {"input/pad", "state", "objects/cup"},
       "sctd-robot": {"target", "gripper", "can"},
       "sctd-input": {"target", "state", "scene", "status", "objects/cup"},
       "sctd-recorder": {"state", "objects/cup", "scene"},
       "sctd-learner": {"demos/pour/d1", "status"},
       "sctd-operator": EVERY,
       # the view (sctd view) draws the input and the objects too
       "sctd-observer": {"target", "gripper", "state", "status", "scene", "learner/status", "input/pad",
                         "objects/cup"}}
ANSWER = {"sctd-runtime": {"skill", "skill/swap", "skill/bundle"}, "sctd-robot": {"sim/reset"},
          "sctd-learner": {"learner"}}
QUERY = {"sctd-input": {"skill"}, "sctd-learner": {"skill", "skill/swap"},
         "sctd-operator": {"skill", "skill/swap", "skill/bundle", "learner", "sim/reset"},
         "sctd-observer": {"skill/bundle"}}


def key(suffix: str) -> str:
    return f"sctd/{ROBOT}/{suffix}"


def make_certs(out: Path, port: int) -> Path:
    r = subprocess.run([sys.executable, "-m", "sctd.cli.main", "certs", "--out", str(out),
                        "--router", f"tls/127.0.0.1:{port}"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture
def pki(tmp_path):
    """(certificate dir, router process) with the router up on a free TLS port."""
    port = free_port()
    out = make_certs(tmp_path / "tls", port)
    router = sctd("router", "--config", str(out / "zenoh" / "router.json5"),
                  log=tmp_path / "router.log")
    try:
        assert wait_for(lambda: "listening on" in (tmp_path / "router.log").read_text(), 20), \
            (tmp_path / "router.log").read_text()
        yield out
    finally:
        stopped(router, tmp_path / "router.log")


def stopped(router: Proc, log: Path) -> None:
    """Stop ``sctd router`` with SIGTERM and check how it ended: by itself, with 0 (its
    session closed) or 3 (Zenoh did not close it within 2 s; the router says so and
    exits without it). What these tests check is the access control, so either is
    fine here (``tests/test_router.py`` tells them apart); a router that had to be
    killed (-9) is not."""
    rc = router.stop()
    assert rc in (EXIT_OK, EXIT_FORCED), (rc, log.read_text())
    assert (rc == EXIT_FORCED) == ("did not close" in log.read_text()), (rc, log.read_text())


class Sessions:
    """Zenoh sessions opened in a test, closed at its end."""

    def __init__(self, tls: Path):
        self.tls = tls
        self.open: list[zenoh.Session] = []

    def role(self, role: str) -> zenoh.Session:
        return self.config(zenoh.Config.from_file(str(self.tls / "zenoh" / f"{role}.json5")))

    def config(self, conf: zenoh.Config) -> zenoh.Session:
        s = zenoh.open(conf)
        self.open.append(s)
        return s

    def close(self) -> None:
        for s in self.open:
            close_session(s)


@pytest.fixture
def sessions(pki):
    ss = Sessions(pki)
    yield ss
    ss.close()


def counting(s: zenoh.Session, suffixes, counts: Counter, tag: str = ""):
    subs = []
    for suffix in suffixes:
        def cb(sample, suffix=suffix):
            counts[tag + suffix] += 1
        subs.append(s.declare_subscriber(key(suffix), cb))
    return subs


def put_all(s: zenoh.Session, suffixes) -> None:
    for _ in range(N):
        for suffix in suffixes:
            s.put(key(suffix), b"{}")
        time.sleep(0.005)


def answering(s: zenoh.Session, suffixes, name: str, asked: Counter):
    qs = []
    for suffix in suffixes:
        def cb(query, suffix=suffix):
            asked[suffix] += 1
            query.reply(query.key_expr, name.encode())
        qs.append(s.declare_queryable(key(suffix), cb))
    return qs


def answers(s: zenoh.Session, suffix: str, timeout: float = 1.5) -> set[str]:
    got = set()
    for reply in s.get(key(suffix), consolidation=zenoh.ConsolidationMode.NONE, timeout=timeout):
        if reply.ok is not None:
            got.add(reply.ok.payload.to_bytes().decode())
    return got


@pytest.mark.parametrize("role", ROLES)
def test_role_may_exactly_what_the_table_says(sessions, role):
    """``role`` publishes every key: only its own reach a watcher; it subscribes every
    key: only the table's arrive; it answers and asks every queryable: only the table's
    go through."""
    got: Counter = Counter()
    watcher = sessions.role("sctd-operator")
    subs = counting(watcher, EVERY, got, "watch:")
    me_sub = sessions.role(role)
    subs += counting(me_sub, EVERY, got, "me:")
    me = sessions.role(role)
    owners = {r: sessions.role(r) for r in set(OWNER.values()) | set(ANSWERS.values())}
    asked: Counter = Counter()
    mine_asked: Counter = Counter()
    qs = [q for r, s in owners.items()
          for q in answering(s, [k for k, v in ANSWERS.items() if v == r], r, asked)]
    qs += answering(me, ANSWERS, f"{role} (test)", mine_asked)
    time.sleep(0.5)  # declarations propagate

    # publishing: the role's own keys reach the watcher in full, nothing else does
    put_all(me, EVERY)
    for k in PUB[role]:
        assert wait_for(lambda k=k: got["watch:" + k] >= N, 15), (k, got)
    # subscribing: every owner publishes its key; the table's keys reach the role in full
    for k, owner in OWNER.items():
        put_all(owners[owner], [k])
    for k in EVERY:
        assert wait_for(lambda k=k: got["watch:" + k] >= N * (1 + (k in PUB[role])), 15), (k, got)
    for k in SUB[role]:
        assert wait_for(lambda k=k: got["me:" + k] >= N * (1 + (k in PUB[role])), 15), (k, got)
    time.sleep(0.5)  # anything still on the way
    for k in EVERY:
        assert got["watch:" + k] == N * (1 + (k in PUB[role])), (role, "published", k, got)
        # the role's own puts count too where it both publishes and subscribes (can)
        sent = N * (1 + (k in PUB[role]))
        assert got["me:" + k] == (sent if k in SUB[role] else 0), (role, "subscribed", k, got)

    # queries: the operator reaches the owners, and the role's answers only where allowed
    for k, owner in ANSWERS.items():
        expect = {owner} | ({f"{role} (test)"} if k in ANSWER.get(role, set()) else set())
        assert wait_for(lambda k=k, e=expect: answers(watcher, k) == e, 15), (role, k)
        assert answers(watcher, k) == expect, (role, "answered", k)
    before = Counter(asked)
    for k, owner in ANSWERS.items():
        allowed = k in QUERY.get(role, set())
        assert (owner in answers(me_sub, k)) == allowed, (role, "queried", k)
        if not allowed:
            assert asked[k] == before[k], (role, "query reached", k)
    del subs, qs


def intruder_config(tls: Path, kind: str, tmp: Path, port: int) -> zenoh.Config:
    """A client config for one kind of stranger."""
    if kind == "plain-tcp":
        conf = zenoh.Config()
        conf.insert_json5("mode", '"client"')
        conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
        conf.insert_json5("scouting/multicast/enabled", "false")
    else:
        conf = zenoh.Config.from_file(str(tls / "zenoh" / "sctd-observer.json5"))
        if kind == "no-client-cert":
            conf.insert_json5("transport/link/tls/connect_certificate", "null")
            conf.insert_json5("transport/link/tls/connect_private_key", "null")
            conf.insert_json5("transport/link/tls/enable_mtls", "false")
        elif kind == "other-ca":
            other = make_certs(tmp / "other", port)
            conf.insert_json5("transport/link/tls/connect_certificate",
                              json.dumps(str(other / "sctd-runtime.pem")))
            conf.insert_json5("transport/link/tls/connect_private_key",
                              json.dumps(str(other / "sctd-runtime-key.pem")))
        elif kind == "unlisted-cn":
            cert, keyf = sign(tls, "intruder", tmp)
            conf.insert_json5("transport/link/tls/connect_certificate", json.dumps(str(cert)))
            conf.insert_json5("transport/link/tls/connect_private_key", json.dumps(str(keyf)))
    conf.insert_json5("connect/timeout_ms", "3000")
    return conf


def sign(tls: Path, cn: str, tmp: Path) -> tuple[Path, Path]:
    """A certificate with common name ``cn`` signed by the deployment's own CA."""
    keyf, csr, cert, ext = (tmp / f"{cn}-key.pem", tmp / f"{cn}.csr", tmp / f"{cn}.pem",
                            tmp / f"{cn}.ext")
    ext.write_text("basicConstraints=critical,CA:FALSE\nextendedKeyUsage=clientAuth\n")
    for argv in (["req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
                  "-subj", f"/CN={cn}", "-keyout", str(keyf), "-out", str(csr)],
                 ["x509", "-req", "-in", str(csr), "-CA", str(tls / "ca.pem"), "-CAkey",
                  str(tls / "ca-key.pem"), "-CAcreateserial", "-CAserial", str(tmp / "ca.srl"),
                  "-days", "2", "-extfile", str(ext), "-out", str(cert)]):
        r = subprocess.run(["openssl", *argv], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
    return cert, keyf


def router_port(tls: Path) -> int:
    text = (tls / "zenoh" / "sctd-runtime.json5").read_text()
    return int(text.split("tls/127.0.0.1:")[1].split('"')[0])


@pytest.mark.parametrize("kind", ["plain-tcp", "no-client-cert", "other-ca", "unlisted-cn",
                                  "observer"])
def test_intruder_delivers_nothing(sessions, tmp_path, kind):
    """A stranger publishes every key of the contract and asks skill, skill/swap and
    learner: nothing arrives, no queryable is asked (the observer reads the active bundle,
    ``skill/bundle``, and nothing else). Without a certificate of the CA the router
    refuses the link itself."""
    got: Counter = Counter()
    watcher = sessions.role("sctd-operator")
    subs = counting(watcher, EVERY, got)
    asked: Counter = Counter()
    qs = answering(sessions.role("sctd-runtime"), ["skill", "skill/swap", "skill/bundle"], "runtime", asked)
    qs += answering(sessions.role("sctd-learner"), ["learner"], "learner", asked)
    control = sessions.role("sctd-robot")
    conf = (zenoh.Config.from_file(str(sessions.tls / "zenoh" / "sctd-observer.json5"))
            if kind == "observer" else
            intruder_config(sessions.tls, kind, tmp_path, router_port(sessions.tls)))
    if kind in ("plain-tcp", "no-client-cert", "other-ca"):
        with pytest.raises(zenoh.ZError):
            sessions.config(conf)
        return
    intruder = sessions.config(conf)
    # Barriers instead of sleeps: a link carries its messages in order, so once the
    # watcher's query is answered the router has the watcher's subscriptions (declared
    # before the query on the same link) and the runtime's queryable.
    assert wait_for(lambda: answers(watcher, "skill/swap") == {"runtime"}, 15)
    asked_before = Counter(asked)
    put_all(intruder, EVERY)
    put_all(control, ["state"])
    # (the router takes the intruder's puts before its queries, which have ended here)
    replies = {k: answers(intruder, k) for k in ("skill/swap", "learner", "skill", "skill/bundle")}
    assert wait_for(lambda: got["state"] >= N, 15), got
    asked_by_intruder = Counter(asked) - asked_before
    # The watcher reaches the queryables still (the denial is the stranger's), and the
    # answer comes over the router's link to the watcher after whatever the router had
    # forwarded of the intruder's puts: the counts below are final.
    assert answers(watcher, "skill/swap") == {"runtime"}
    assert {k: got[k] for k in EVERY} == {k: N if k == "state" else 0 for k in EVERY}
    reads = {"skill/bundle"} if kind == "observer" else set()
    assert replies == {k: {"runtime"} if k in reads else set()
                       for k in ("skill/swap", "learner", "skill", "skill/bundle")}, replies
    assert asked_by_intruder == Counter(reads), asked_by_intruder
    del subs, qs


def test_usrpwd_roles_by_user_name(tmp_path):
    """With ``sctd certs --usrpwd`` the user name is the role: the input may publish input
    and not target; a wrong password and no password are refused by the router."""
    port = free_port()
    r = subprocess.run([sys.executable, "-m", "sctd.cli.main", "certs", "--out",
                        str(tmp_path / "tls"), "--router", f"tls/127.0.0.1:{port}", "--usrpwd"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    udir = tmp_path / "tls" / "zenoh" / "usrpwd"
    assert (tmp_path / "tls" / "users.txt").stat().st_mode & 0o077 == 0
    log = tmp_path / "router.log"
    router = sctd("router", "--config", str(udir / "router.json5"), log=log)
    ss = Sessions(tmp_path / "tls")
    try:
        assert wait_for(lambda: "listening on" in log.read_text(), 20), log.read_text()
        got: Counter = Counter()
        runtime = ss.config(zenoh.Config.from_file(str(udir / "sctd-runtime.json5")))
        operator = ss.config(zenoh.Config.from_file(str(udir / "sctd-operator.json5")))
        subs = counting(runtime, ["input/pad"], got, "runtime:")
        subs += counting(operator, ["target", "input/pad"], got, "operator:")
        user = ss.config(zenoh.Config.from_file(str(udir / "sctd-input.json5")))
        time.sleep(0.5)
        put_all(user, ["target", "input/pad"])
        assert wait_for(lambda: got["runtime:input/pad"] >= N and got["operator:input/pad"] >= N,
                        15), got
        time.sleep(0.5)
        assert got == {"runtime:input/pad": N, "operator:input/pad": N}
        for password in ("wrong", None):
            conf = zenoh.Config.from_file(str(udir / "sctd-runtime.json5"))
            conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
            conf.insert_json5("connect/timeout_ms", "3000")
            with pytest.raises(zenoh.ZError):
                ss.config(conf)
        del subs
    finally:
        ss.close()
        stopped(router, log)


def test_client_query_finds_the_queryable_only_where_allowed(sessions):
    """``sctd.wire.client.query`` waits for a matching queryable before its get: the
    router's declarations reach the input (may ask ``skill``) and not the observer, and an
    error reply passes like an answer."""
    from sctd.wire import client, codec

    asked: Counter = Counter()
    runtime = sessions.role("sctd-runtime")
    qs = [runtime.declare_queryable(key("skill"), lambda q: (
        asked.update(["skill"]), q.reply(q.key_expr, codec.pack({"skill": "pour"}))))]
    qs.append(runtime.declare_queryable(key("skill/swap"), lambda q: (
        asked.update(["skill/swap"]), q.reply_err(codec.pack({"error": "bad bundle"})))))
    user, observer = sessions.role("sctd-input"), sessions.role("sctd-observer")
    learner = sessions.role("sctd-learner")
    assert client.query(user, key("skill"), find=10.0) == (True, {"skill": "pour", "v": 1})
    refused = (False, {"error": "bad bundle", "v": 1})
    assert client.query(learner, key("skill/swap"), b"x", find=10.0) == refused
    assert client.query(observer, key("skill"), find=2.0) is None
    assert client.query(observer, key("skill/swap"), b"x", find=2.0) is None
    assert client.query(observer, key("skill"), find=2.0, parameters="bundle") is None
    assert client.query(user, key("skill/swap"), b"x", find=2.0) is None
    assert client.query(learner, key("skill"), find=10.0) == (True, {"skill": "pour", "v": 1})
    assert asked == Counter({"skill": 2, "skill/swap": 1})
    del qs


def test_publisher_reaches_a_wildcard_subscriber(sessions):
    """A Zenoh Publisher (as ``sctd sim`` and ``sctd run`` declare) sends only while it
    knows a matching subscriber: the operator's ``sctd/**`` must be declared to the robot
    even though the robot publishes only its own keys; the observer's ``sctd/**`` is
    refused."""
    got: Counter = Counter()
    operator, observer = sessions.role("sctd-operator"), sessions.role("sctd-observer")
    # a session delivers to all its matching subscribers whatever arrives, so the
    # refused wildcard gets a session of its own
    wide = sessions.role("sctd-observer")
    subs = [operator.declare_subscriber("sctd/**", lambda s: got.update(["operator"])),
            wide.declare_subscriber("sctd/**", lambda s: got.update(["observer"])),
            observer.declare_subscriber(key("state"), lambda s: got.update(["observer:state"]))]
    robot = sessions.role("sctd-robot")
    pub = robot.declare_publisher(key("state"))
    assert wait_for(lambda: pub.matching_status.matching, 15)
    for _ in range(N):
        pub.put(b"{}")
        time.sleep(0.005)
    assert wait_for(lambda: got["operator"] >= N and got["observer:state"] >= N, 15), got
    time.sleep(0.5)
    assert got == {"operator": N, "observer:state": N}
    pub.undeclare()
    del subs
