"""sctd across real hosts: network namespaces on this machine, one per host, joined by
a bridge, every program a client of a Zenoh router (``sctd.bench.multihost.Cluster``).

Needs root (``ip netns add``). Without it the tests skip and say why, except in CI
(``$CI`` set), where they fail instead: there they must run.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest

from sctd.bench.multihost import Cluster
from sctd.bench.netns import Hosts, NamespaceError, can_make_namespaces, namespaces
from sctd.cli.errors import EXIT_FORCED, EXIT_OK
from sctd.runtime.controller import RuntimeConfig
from tests.conftest import wait_for

STATE_TIMEOUT_S = RuntimeConfig().state_timeout
RATE_HZ = RuntimeConfig().rate


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    why = can_make_namespaces()
    if why is not None:
        if os.environ.get("CI"):
            pytest.fail(f"network namespaces cannot be made in CI: {why}")
        pytest.skip(f"network namespaces cannot be made here: {why}")
    logdir = tmp_path_factory.mktemp("multihost")
    c = Cluster(logdir)
    try:
        c.__enter__()
    except NamespaceError as e:
        pytest.fail(f"making the hosts failed: {e}")
    try:
        c.start_router()
        c.procs = {"robot": c.start_robot(), "runtime": c.start_runtime(),
                   "observer": c.start_observer()}
        assert wait_for(lambda: c.first(c.keys.target), 60), _logs(c)
        yield c
    finally:
        run_id = c.hosts.run_id
        try:
            # sctd router's own ending: 0 its session closed, 3 Zenoh did not close it
            # within 2 s (it says so); never a kill
            router_rc = c.stop_router()
            router_log = "" if c.router is None else c.router.output()[-2000:]
        finally:
            c.__exit__(None, None, None)
        assert namespaces(run_id) == [], f"namespaces left over: {namespaces(run_id)}"
        assert router_rc in (None, EXIT_OK, EXIT_FORCED), (router_rc, router_log)


def test_hosts_clean_up_everything_after_an_exception(tmp_path):
    why = can_make_namespaces()
    if why is not None:
        if os.environ.get("CI"):
            pytest.fail(f"network namespaces cannot be made in CI: {why}")
        pytest.skip(f"network namespaces cannot be made here: {why}")
    hosts = Hosts(["a", "b"], tmp_path)
    with pytest.raises(RuntimeError, match="a test failing inside"), hosts:
        assert len(hosts.leftovers()) == 3  # a, b and the switch
        sleeper = hosts.run("a", ["sleep", "300"], "sleep.log")
        # a grandchild in its own session, which stopping the child does not reach
        hosts.run("b", ["sh", "-c", "setsid sleep 300 & wait"], "orphan.log")
        assert wait_for(lambda: len(subprocess.run(["ip", "netns", "pids", hosts.ns("b")],
                                                   capture_output=True, text=True).stdout.split()) >= 2)
        raise RuntimeError("a test failing inside the hosts")
    assert hosts.leftovers() == []
    assert sleeper.p.poll() is not None
    assert subprocess.run(["ip", "link", "show", "br0"], capture_output=True).returncode != 0


def _logs(c: Cluster) -> str:
    return "\n".join(f"--- {p.log_path.name}\n{p.output()[-3000:]}" for p in c.hosts._procs)


def _status(c: Cluster, since: float = 0.0) -> list[dict]:
    return [r["msg"] for r in c.seen(c.keys.status, since)]


def test_pour_completes_across_hosts(cluster):
    c = cluster
    report = c.user(150)  # it stops when done (30-40 s here; ~100 s on a machine under load)
    assert report["done"] and report["final_state"] == "pour", report
    # the robot host's own verdict, as the observer host received it
    assert wait_for(lambda: any(r["msg"].get("success") for r in c.seen(c.keys.scene)), 10), \
        (c.last(c.keys.scene), _logs(c))
    assert all(p.running() for p in c.procs.values()), _logs(c)


def test_router_restart_every_program_reconnects_and_the_runtime_holds(cluster):
    c = cluster
    steady = c.start_steady_input()
    try:
        t_start = time.time()
        assert wait_for(lambda: any(m["mode"] == "running" and m["in_seq"] >= 0
                                    for m in _status(c, t_start)), 30), _logs(c)
        time.sleep(1.0)
        before_input = _status(c, t_start)[-1]["in_seq"]  # the steady input's seq by now
        assert c.router is not None
        assert c.router.kill() == -signal.SIGKILL
        t_kill = time.time()
        time.sleep(3.0)  # much longer than the state timeout
        t_restart = time.time()
        c.start_router()
        # every program is back: the robot (state, scene), the runtime (target,
        # status) and the input host (the runtime follows newer input again)
        assert wait_for(lambda: c.first(c.keys.state, t_restart) and c.first(c.keys.scene, t_restart)
                        and any(m["mode"] == "running" and m["in_seq"] > before_input
                                for m in _status(c, t_restart)), 60), _logs(c)
        before = [r["msg"] for r in c.seen(c.keys.target) if r["t"] < t_kill][-1]
        after = c.first(c.keys.target, t_restart)["msg"]
        # The runtime held: between the last target before the router died and the
        # first after it came back (the runtime's own seq and stamps) it published
        # only what its state timeout allows, not one target per tick.
        gap_s = after["stamp"] - before["stamp"]
        published = after["seq"] - before["seq"] - 1
        assert gap_s > 2.5, (before, after)
        assert published < 0.5 * RATE_HZ * gap_s, (published, gap_s)
        stale = [m["counters"]["stale_state"] for m in _status(c)]
        assert stale[-1] > min(stale), "the runtime never saw its state go stale"
        # and the arm did not move: the robot's pose after the restart is the pose it
        # had before (the stick was at rest, so nothing should have moved it)
        p0 = [r["msg"]["pose"] for r in c.seen(c.keys.state) if r["t"] < t_kill][-1]
        p1 = c.first(c.keys.state, t_restart)["msg"]["pose"]
        assert max(abs(a - b) for a, b in zip(p0[:3], p1[:3], strict=True)) < 1e-3, (p0, p1)
    finally:
        steady.stop()


def test_robot_link_down_holds_within_the_state_timeout_and_recovers(cluster):
    c = cluster
    steady = c.start_steady_input()
    try:
        t_start = time.time()
        assert wait_for(lambda: any(m["mode"] == "running" for m in _status(c, t_start)), 30), _logs(c)
        t_down = time.time()
        c.hosts.link("robot", False)
        assert wait_for(lambda: sum(m["mode"] == "hold" for m in _status(c, t_down)) >= 10, 10), \
            _status(c, t_down)[-5:]
        c.hosts.link("robot", True)
        t_up = time.time()
        assert wait_for(lambda: any(m["mode"] == "running" for m in _status(c, t_up)), 30), _logs(c)
        during = _status(c, t_down)
        # Once the state is older than the timeout (plus the tick that notices it) the
        # runtime is in hold, every status says so, and no target goes out.
        late = [m for m in during
                if m["state_age"] is not None and m["state_age"] > STATE_TIMEOUT_S + 2.0 / RATE_HZ]
        assert late and all(m["mode"] == "hold" for m in late), [(m["mode"], m["state_age"]) for m in late]
        held = [m["targets"] for m in late]
        assert held[0] == held[-1], f"targets published while the state was stale: {held[0]} -> {held[-1]}"
    finally:
        steady.stop()


@pytest.fixture(scope="module")
def intrusion(cluster):
    """What the intruders got through (``Cluster.intrude``), the runtime's swap counters
    before and after, with the learner up and the input host sending."""
    c = cluster
    assert c.secure, "sctd certs / sctd router are missing: the cluster runs on plain TCP"
    learner, steady = c.start_learner(), c.start_steady_input()
    try:
        assert wait_for(lambda: c.first(c.keys.learner_status), 60), _logs(c)
        before = _status(c)[-1]["counters"]
        result = c.intrude()
        t_end = time.time()
        assert wait_for(lambda: _status(c, t_end), 10), _logs(c)
        after = _status(c, t_end)[-1]["counters"]
        yield result, before, after
    finally:
        steady.stop()
        learner.stop()


def test_allowed_senders_and_queries_get_through(intrusion):
    """The control: what the intruders fail at works for the roles that may do it, so a
    0 below means refused, not lost."""
    result, _, _ = intrusion
    control = result["control"]
    assert sum(control["delivered"].values()) == control["sent"] == control["tried"], control
    assert control["summary"]["ok"] == 1, control  # the operator reads the skill summary
    assert control["swap"]["ok"] + control["swap"]["err"] == 1, control  # the runtime answers
    assert control["train"]["ok"] + control["train"]["err"] == 1, control  # the learner answers


@pytest.mark.parametrize("who", ["no-certificate", "other-ca", "unlisted-name", "observer"])
def test_intruder_delivers_nothing_and_cannot_swap_or_train(intrusion, who):
    result, before, after = intrusion
    got = result[who]
    assert got["tried"] > 0
    assert got["delivered"] == {}, f"{who} delivered {got['delivered']} of {got['tried']}"
    for ask in ("swap-on-skill", "swap", "train"):
        assert got[ask]["ok"] == got[ask]["err"] == 0, (who, ask, got[ask])
    # the runtime refused only the operator's malformed bundle (the control), nothing else
    control_swaps = result["control"]["swap"]["ok"] + result["control"]["swap"]["err"]
    assert after["swaps"] == before["swaps"], (before, after)
    assert after["swaps_refused"] - before["swaps_refused"] == control_swaps, (before, after)
    received = {k.rsplit("edan/", 1)[1]: n for k, n in got["received"].items() if n}
    if who == "observer":
        # a tablet sees what the table allows it, and nothing else
        assert set(received) <= {"target", "state", "status", "scene", "learner/status"}, received
        assert {"target", "state", "status"} <= set(received), received
    else:  # it reads nothing at all
        assert received == {}, received
    if who in ("no-certificate", "other-ca"):
        assert got["refused"], got  # TLS did not let it in at all
    # a certificate of our CA with a name that is no role connects (TLS is satisfied)
    # and is denied everything by the access control: the checks above
