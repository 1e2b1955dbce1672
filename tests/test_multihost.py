"""sctd across real hosts: network namespaces on this machine, one per host, joined by
a bridge, every program a client of a Zenoh router (``sctd.deploy.cluster.Cluster``).

Needs root (``ip netns add``). Without it the tests skip and say why, except in CI
(``$CI`` set), where they fail instead: there they must run.
"""

from __future__ import annotations

import json
import signal
import subprocess
import time

import pytest

from sctd.app.defaults import defaults
from sctd.deploy.cluster import Cluster
from sctd.deploy.netns import Hosts
from sctd.runtime.controller import RuntimeConfig
from sctd.task import find_task
from tests.conftest import require_namespaces, running_cluster, wait_for

pytestmark = [pytest.mark.slow, pytest.mark.realtime]  # network namespaces, a process per host

STATE_TIMEOUT_S = RuntimeConfig().state_timeout
RATE_HZ = RuntimeConfig().rate
OBSERVER_HZ = 100.0  # the observer keeps at most this many samples a second of each key
OUTAGE_S = 3.0  # s the router is down: 30 state timeouts
REST_WINDOW_S = 0.5  # s of the robot's stamps over which the hand must be still ...
REST_SPREAD_M = 1e-4  # ... within this (m) of its newest position
HAND_BOUND_M = 1e-3  # m the hand at rest may move across the outage (derived in the test)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    with running_cluster(tmp_path_factory.mktemp("multihost"), task=find_task(defaults().task)) as c:
        c.procs = {"robot": c.start_robot(), "runtime": c.start_runtime(),
                   "observer": c.start_observer()}
        assert wait_for(lambda: c.first(c.keys.target), 60), _logs(c)
        yield c


def test_hosts_clean_up_everything_after_an_exception(tmp_path):
    require_namespaces()
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


def test_a_log_folder_used_before_gives_each_program_and_cluster_only_its_own(tmp_path):
    """A resumed sweep (``sctd bench link --record``) starts its clusters in the folder of
    the run it takes up: a new CA replaces the old one, a program's output starts at its
    own line (a proxy's "ready" of the last run is not this one's) and the observer's
    earlier records are not this cluster's."""
    require_namespaces()
    with Hosts(["a"], tmp_path) as hosts:
        first = hosts.run("a", ["sh", "-c", "echo first-run"], "x.log")
        assert first.p.wait(10) == 0
        second = hosts.run("a", ["sh", "-c", "echo second-run"], "x.log")
        assert second.p.wait(10) == 0
        assert "second-run" in second.output() and "first-run" not in second.output()
        assert "first-run" in first.output() and "second-run" in (tmp_path / "x.log").read_text()
    task = find_task(defaults().task)
    with Cluster(tmp_path / "c", task=task) as c:
        first_ca = (tmp_path / "c" / "tls" / "ca.pem").read_bytes() if c.secure else b""
    stale = {"key": c.keys.status, "t": time.time(), "msg": {"seq": 1}}
    (tmp_path / "c" / "observer.jsonl").write_text(json.dumps(stale) + "\n")
    with Cluster(tmp_path / "c", task=task) as c:
        assert c.first(c.keys.status) is None
        if c.secure:
            assert (tmp_path / "c" / "tls" / "ca.pem").read_bytes() != first_ca
    assert c.hosts.leftovers() == []


def _logs(c: Cluster) -> str:
    return "\n".join(f"--- {p.log_path.name}\n{p.output()[-3000:]}" for p in c.hosts._procs)


def _brief(record: dict | None) -> str:
    """A scene message's outcome first (what a failed pour's assertion needs to say)."""
    if record is None:
        return "none"
    msg = record["msg"]
    first = {k: msg[k] for k in ("success", "done", "poured", "spilled_amount", "radial", "tilt", "reason",
                                      "skipped", "behind_s")
             if k in msg}
    return f"{first} (keys {sorted(msg)})"


def _status(c: Cluster, since: float = 0.0) -> list[dict]:
    return [r["msg"] for r in c.seen(c.keys.status, since)]


def test_pour_completes_across_hosts(cluster):
    c = cluster
    report = c.user(150)  # it stops when done (30-40 s here; ~100 s on a machine under load)
    assert report["done"] and report["final_state"] == "pour", report
    # the robot host's own verdict, as the observer host received it: the pour is over
    assert wait_for(lambda: any(r["msg"].get("done") for r in c.seen(c.keys.scene)), 10), \
        f"the user's report {report}\nthe last scene {_brief(c.last(c.keys.scene))}\n{_logs(c)}"
    verdict = [r["msg"] for r in c.seen(c.keys.scene) if r["msg"].get("done")][-1]
    # ... a success by the task's rules: not a drop spilled, not the bottle emptied. (A
    # spill of a few percent here once came from the simulated arm's controller at the
    # wrist's singularity, not from the link: sim/controller.py says why and how.)
    assert verdict.get("success") and verdict.get("spilled_amount") == 0.0, \
        f"the user's report {report}\nthe verdict {_brief({'msg': verdict})}\n{_logs(c)}"
    assert all(p.running() for p in c.procs.values()), _logs(c)


def test_the_view_reads_everything_it_draws_with_the_observer_certificate(cluster):
    """``sctd view`` on the observer host, a Zenoh client of the router with the
    ``sctd-observer`` certificate: the access policy lets it read the state, the target,
    the status, the scene, the task's objects, the input and the active skill's bundle
    (the skill it draws is the one the runtime runs)."""
    from sctd.deploy.netns import last_json
    from sctd.skill import bundle_from_file
    from sctd.skill.catalog import find_skill

    c = cluster
    steady = c.start_steady_input()
    view = c.start_view(15)
    try:
        assert wait_for(lambda: view.p.poll() is not None, 90), view.output()[-3000:]
    finally:
        view.stop()
        steady.stop()
    assert view.p.returncode == 0, view.output()[-3000:]
    report = last_json(view.output())
    assert report is not None, view.output()[-3000:]
    assert report["skills"] == [bundle_from_file(find_skill(c.skill)).id], report
    assert report["fetch_failures"] == 0 and report["dropped"] == 0, report
    read = report["read"]
    for k in ("state", "target", "status", "scene", f"objects/{c.task.object}", "input/steady"):
        assert read.get(k, 0) > 0, (k, report)


def _by_seq(c: Cluster, key: str) -> list[dict]:
    """The messages the observer recorded on ``key``, in their sender's ``seq`` order."""
    return sorted((r["msg"] for r in c.seen(key)), key=lambda m: m["seq"])


def _at_rest(c: Cluster) -> dict | None:
    """The newest state when the robot's own reports say the hand is still: over the
    last ``REST_WINDOW_S`` of its stamps (at least half the samples the observer keeps
    of them), every position within ``REST_SPREAD_M`` of the newest; else None."""
    states = _by_seq(c, c.keys.state)
    if not states:
        return None
    last = states[-1]
    window = [m for m in states if m["stamp"] >= last["stamp"] - REST_WINDOW_S]
    if len(window) == len(states) or len(window) < 0.5 * REST_WINDOW_S * OBSERVER_HZ:
        return None
    spread = max(abs(a - b) for m in window for a, b in zip(m["pose"][:3], last["pose"][:3], strict=True))
    return last if spread <= REST_SPREAD_M else None


def _input_flows(c: Cluster) -> int | None:
    """The input seq of the runtime's newest status when it is running on an input
    that still arrives (its ``in_seq`` newer than in the status before), else None."""
    st = sorted(_status(c), key=lambda m: m["stamp"])[-2:]
    if len(st) == 2 and all(m["mode"] == "running" for m in st) and st[1]["in_seq"] > st[0]["in_seq"]:
        return int(st[1]["in_seq"])
    return None


def _outage(msgs: list[dict]) -> tuple[dict, dict]:
    """The two consecutive messages (by seq) with the longest time between their
    stamps: the last one sent before the router went down that reached the observer,
    and the first one after it came back."""
    i = max(range(1, len(msgs)), key=lambda i: msgs[i]["stamp"] - msgs[i - 1]["stamp"])
    return msgs[i - 1], msgs[i]


def test_router_restart_every_program_reconnects_and_the_runtime_holds(cluster):
    """The router is killed and started again ``OUTAGE_S`` later; every program
    reconnects, the runtime held meanwhile, and the hand, at rest before, is where it
    was.

    Everything asserted comes from the programs' own reports (seq, stamps, counters,
    poses): the outage is the longest silence between two consecutive messages of the
    robot (states) and of the runtime (targets) that the observer recorded.

    The hand's bound, 1 mm, holds for a hand at rest: the stick at rest and the hand
    still by the robot's reports (within ``REST_SPREAD_M`` over ``REST_WINDOW_S``).
    The simulator's controller (``sctd_sim.controller``) is a spring ``k_trans`` =
    3000 N/m with critical damping. When the targets stop it holds the pose it
    measures ``target_timeout`` (0.1 s) later; when they come back the runtime re-seeds
    its target at the measured pose. Each moves the spring's set point by the static
    deflection ``e = w / k_trans``, ``w`` the wrench at the hand that the controller
    does not cancel. Gravity, Coriolis and the bottle are modelled exactly and
    friction is zero at rest, which leaves the rounding of the torque commands on the
    CAN bus (0.01 N m steps, ``sim/edan_joints.dbc``): at most 0.06 N at the hand at
    the pour's end posture, so e <= 0.02 mm. The reported pose is the forward
    kinematics of encoder positions in 1e-4 rad steps; there the columns of the
    translational Jacobian add up to 2.87 m/rad, so two reports of a hand that has not
    moved can differ by up to 0.29 mm. With the rest spread that makes at most
    2 x 0.02 + 0.29 + 0.1 = 0.43 mm; measured across 23 restarts of the cluster, with
    and without busy loops beside: 0.002-0.012 mm.

    Only a hand that is moving when the targets stop goes past 1 mm: it travels on by
    about v x 11 ms (the task-space modes there have 1.0-5.6 kg, so omega =
    sqrt(k / Lambda) = 23-54 rad/s; simulated: 0.53, 1.08 and 2.8 mm at 0.05, 0.1 and
    0.25 m/s). The 1.84 mm seen once (not reproduced in those 23 restarts) is what a
    hand at about 0.17 m/s gives. The test did not check the rest then: its wait for a
    running status could be met by a late status from the simulated user's time, and
    it took its "before" pose by its own clock (the last state the observer had
    received when the test killed the router), while on the loaded machine states
    reached the observer up to 2.3 s late. Now a hand that does not come to rest fails
    the wait, and one that moves across the outage fails the bound, with both poses.
    """
    c = cluster
    steady = c.start_steady_input()
    try:
        # the steady input drives the runtime and the hand is still, by their reports
        # (kept as found: asked again, a status that arrived since could say otherwise)
        found: dict = {}

        def ready() -> bool:
            flows, still = _input_flows(c), _at_rest(c)
            if flows is None or still is None:
                return False
            found.update(rest=still, before_input=flows)
            return True
        assert wait_for(ready, 60, interval=0.1), \
            ("no running status on flowing input with the hand at rest", _status(c)[-3:],
             _by_seq(c, c.keys.state)[-3:], _logs(c))
        rest, before_input = found["rest"], found["before_input"]
        # the newest target the observer has: its stamp may be older than the rest
        # state's (the kill can follow that state by a few ms, before the next target
        # is recorded), so the outage is looked for from this target on
        last_target = _by_seq(c, c.keys.target)[-1]
        assert c.router is not None
        assert c.router.kill() == -signal.SIGKILL
        time.sleep(OUTAGE_S)  # the outage itself (its length is checked on the stamps below)
        c.start_router()
        # every program is back: the robot (state, scene), the runtime (target,
        # status) and the input host (the runtime follows newer input again), each
        # seen with a stamp that only a message sent after the outage can have
        back = rest["stamp"] + OUTAGE_S

        def is_back(key: str, ok=lambda m: True) -> bool:
            return any(m["stamp"] > back and ok(m) for m in (r["msg"] for r in c.seen(key)))

        assert wait_for(lambda: is_back(c.keys.state) and is_back(c.keys.scene) and is_back(c.keys.target)
                        and is_back(c.keys.status, lambda m: m["mode"] == "running"
                                    and m["in_seq"] > before_input), 60, interval=0.1), _logs(c)
        targets = [m for m in _by_seq(c, c.keys.target) if m["seq"] >= last_target["seq"]]
        before, after = _outage(targets)
        # The runtime held: between the last target before the router died and the
        # first after it came back it published only what its state timeout allows,
        # not one target per tick.
        gap_s = after["stamp"] - before["stamp"]
        published = after["seq"] - before["seq"] - 1
        assert gap_s > OUTAGE_S - 0.5, (before, after)
        assert published < 0.5 * RATE_HZ * gap_s, (published, gap_s)
        stale = [m["counters"]["stale_state"] for m in sorted(_status(c), key=lambda m: m["stamp"])]
        assert stale[-1] > min(stale), "the runtime never saw its state go stale"
        # and the hand did not move: the robot's first pose after the outage is the
        # one it reported last before it
        s0, s1 = _outage([m for m in _by_seq(c, c.keys.state) if m["seq"] >= rest["seq"]])
        assert s1["stamp"] - s0["stamp"] > OUTAGE_S - 0.5, (s0, s1)
        moved = max(abs(a - b) for a, b in zip(s0["pose"][:3], s1["pose"][:3], strict=True))
        assert moved < HAND_BOUND_M, (moved, s0, s1, rest)
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
def test_intruder_delivers_nothing_and_cannot_swap_or_train(cluster, intrusion, who):
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
        # a tablet sees what the table allows it (what the view draws), and nothing else:
        # not can, not the demonstrations
        obj = f"objects/{cluster.task.object}"
        allowed = {"target", "state", "status", "scene", "learner/status", "input/intruder", obj}
        assert set(received) <= allowed, received
        assert {"target", "state", "status", obj, "input/intruder"} <= set(received), received
    else:  # it reads nothing at all
        assert received == {}, received
    if who in ("no-certificate", "other-ca"):
        assert got["refused"], got  # TLS did not let it in at all
    # a certificate of our CA with a name that is no role connects (TLS is satisfied)
    # and is denied everything by the access control: the checks above
