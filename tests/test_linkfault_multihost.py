"""The fault proxy on a cluster link: the input host's link to the router, in network
namespaces (``Cluster.fault``), with the runtime on teleoperation so that input moves
the hand.

- A delay on the input link raises the input -> target latency by about that much:
  the target's stamp (the runtime's clock) minus the stamp of the input message its
  ``in_seq`` names (the input's clock), compared across two inputs, one sent before the
  delay was set and one after.
- A stall on the input link makes the daemon hold: its ``input_age`` grows to the
  stall's length, its targets stand still meanwhile, the input's messages all arrive
  (held, not lost); a stick held through the stall moves nothing afterwards until it
  has been centred (the status says so), and then only on input whose stamp is fresh.

Everything asserted comes from the programs' reports (stamps, seq numbers, the daemon's
status, the recorders' arrival stamps, the proxy's counters), never the test's clock.
Needs root; skips without it, except under CI. ``docs/multihost.md``.
"""

from __future__ import annotations

import itertools
import json
import statistics

import pytest

from sctd.app.defaults import defaults
from sctd.deploy.cluster import Cluster, write_payload
from sctd.deploy.linkfault import LinkFault
from sctd.runtime.controller import RuntimeConfig
from sctd.task import find_task
from tests.conftest import running_cluster, wait_for

pytestmark = [pytest.mark.slow, pytest.mark.realtime]  # namespaces, processes, latencies judged

INPUT_TIMEOUT_S = RuntimeConfig().input_timeout
DELAY_MS = 20.0
PAIRS = 150  # input -> target pairs per phase (3 s at 50 Hz)
STALL_S = 2.0
# bytes/s of the input link in the stall test: twice what the input sends (about 150 bytes
# a message through TLS at 50 Hz), so the stall's backlog drains over about the stall's
# length, its old messages arriving one by one rather than in one burst
LINK_BPS = 15000.0
MOVE = {"u": [0.3, 0.0, 0.0], "buttons": [0, 1, 0]}  # deadman held: 0.03 m/s along x on teleop
REST = {"u": [0.0, 0.0, 0.0], "buttons": [0, 1, 0]}  # deadman held, stick centred
STILL_M = 1e-3  # the target moves less than this while the input is stale (0.03 m/s: 60 mm in 2 s)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    logdir = tmp_path_factory.mktemp("linkfault")
    with running_cluster(logdir, task=find_task(defaults().task), skill="teleop") as c:
        c.input_link = c.fault("input", "router", LinkFault())  # clean until a test sets a fault
        c.inputs = logdir / "inputs.jsonl"  # every input message, not downsampled
        c.procs = {"robot": c.start_robot(), "runtime": c.start_runtime(), "observer": c.start_observer(),
                   "inputs": c.hosts.python("observer", "sctd.deploy.probe", "record", "--config",
                                            str(c.config_on("observer")), "--out", str(c.inputs),
                                            "--key", c.keys.input("*"), "--field", "seq",
                                            "--field", "stamp", log="inputs.log")}
        assert wait_for(lambda: c.first(c.keys.target), 60), _logs(c)
        yield c


def _logs(c: Cluster) -> str:
    return "\n".join(f"--- {p.log_path.name}\n{p.output()[-3000:]}" for p in c.hosts._procs)


def _inputs(c: Cluster, name: str) -> list[dict]:
    """Every message of ``input/<name>`` the observer host received: seq, the sender's
    stamp, and ``t``, its arrival there (the recorder's clock)."""
    if not c.inputs.exists():
        return []
    key = c.keys.input(name)
    out = []
    for line in c.inputs.read_text().splitlines():
        if not line.endswith("}"):
            continue  # the line being written
        r = json.loads(line)
        if r["key"] == key and isinstance(r["msg"], dict):
            out.append({**r["msg"], "t": r["t"]})
    return out


def _targets(c: Cluster, since_stamp: float) -> list[dict]:
    """The targets the observer recorded, stamped after ``since_stamp``, in seq order."""
    return sorted((r["msg"] for r in c.seen(c.keys.target) if r["msg"]["stamp"] > since_stamp),
                  key=lambda m: m["seq"])


def _latencies(c: Cluster, name: str) -> list[float]:
    """Per message of ``input/<name>``: the first recorded target that used it (its
    ``in_seq``) minus the message's stamp (s). The observer keeps 100 targets a second,
    so each is up to 10 ms late, alike in both phases."""
    inputs = _inputs(c, name)
    if not inputs:
        return []
    stamp_of = {m["seq"]: m["stamp"] for m in inputs}
    first: dict[int, float] = {}
    for t in _targets(c, inputs[0]["stamp"]):
        s = t["in_seq"]
        if s in stamp_of and t["stamp"] >= stamp_of[s] and s not in first:
            first[s] = t["stamp"] - stamp_of[s]
    return list(first.values())


def _phase(c: Cluster, name: str) -> list[float]:
    """Input at rest on ``input/<name>`` until ``PAIRS`` of its messages have targets."""
    p = c.start_input({"u": [0.0, 0.0, 0.0], "buttons": [0, 1, 0]}, name=name)
    try:
        assert wait_for(lambda: len(_latencies(c, name)) >= PAIRS, 60, interval=0.2), _logs(c)
    finally:
        p.stop()
    return _latencies(c, name)


def test_a_delay_on_the_input_link_raises_the_input_to_target_latency_by_about_it(cluster):
    c = cluster
    before = _phase(c, "clean")
    c.input_link.set("up", LinkFault(delay_ms=DELAY_MS, jitter=0.2, seed=1))
    counted = c.input_link.counters()["up"]
    after = _phase(c, "delayed")
    rise_ms = (statistics.median(after) - statistics.median(before)) * 1e3
    assert DELAY_MS - 6.0 <= rise_ms <= DELAY_MS + 6.0, \
        (rise_ms, statistics.median(before), statistics.median(after))
    # every chunk the input host sent since went through the delay (the proxy's count)
    up = c.input_link.counters()["up"]
    assert up["delayed"] - counted["delayed"] >= PAIRS, (counted, up)
    c.input_link.set("up", LinkFault())


def _status(c: Cluster, since_stamp: float) -> list[dict]:
    return sorted((r["msg"] for r in c.seen(c.keys.status) if r["msg"]["stamp"] > since_stamp),
                  key=lambda m: m["stamp"])


def _age(m: dict) -> float:
    return m["input_age"] if m["input_age"] is not None else float("inf")


def _still(targets: list[dict]) -> float:
    """How far (m, largest coordinate) ``targets`` went from the first of them."""
    first = targets[0]["pose"][:3] if targets else []
    return max((abs(a - b) for t in targets for a, b in zip(t["pose"][:3], first, strict=True)), default=0.0)


def _rearm(m: dict) -> dict:
    return m["input"].get("rearm", {})


def test_a_push_held_through_a_stall_moves_nothing_after_it_until_the_stick_is_centred(cluster, tmp_path):
    """One device pushes through a 2 s stall of its link, its stick still deflected when
    the link comes back. The stall's backlog drains through a link of ``LINK_BPS``: for
    a while each newest message the daemon gets is an old one (a burst would leave only
    its newest, fresh one, since the newest message wins), then fresh ones arrive. The
    daemon follows none of them: the device's push went stale, so it must send a zero
    first (docs/wire-contract.md, "Several devices"); its status says so (``rearm``,
    ``stale_disarms``). Once the same device sends a zero and pushes again, the hand
    moves, on fresh input only."""
    c = cluster
    c.input_link.set("up", LinkFault(bandwidth=LINK_BPS))
    stick = tmp_path / "stick.json"
    write_payload(stick, REST)  # from rest: a gap as the sender starts up moves nothing either
    mover = c.start_input(stick, name="move")
    try:
        start, fresh_again, centred = _stall_then_centre(c, stick)
        counters = c.input_link.counters()
    finally:
        mover.stop()
        c.input_link.set("up", LinkFault())
    statuses = _status(c, start)
    # the daemon's own report: the input it holds grew as old as the stall
    assert STALL_S - 0.2 <= max(map(_age, statuses)) <= STALL_S + 0.6, max(map(_age, statuses))
    stale = [m["stamp"] for m in statuses if _age(m) > INPUT_TIMEOUT_S + 0.05]
    # from the stall until the zero, fresh input included, the target stood still ...
    held = [t for t in _targets(c, start) if stale[0] <= t["stamp"] <= centred]
    assert len(held) > 100, (len(held), stale[0], centred)
    assert _still(held) < STILL_M, _still(held)
    # ... while the daemon said why: the device must centre its stick after a stale push
    told = [m for m in statuses if fresh_again <= m["stamp"] < centred]
    assert told and all(_rearm(m).get("move") == "stale" and m["input"]["owner"] is None for m in told), told
    assert statuses[-1]["counters"]["stale_disarms"] >= 1, statuses[-1]["counters"]
    _held_not_lost_and_fresh_moves(c, centred)
    assert counters["stalls"] >= 1 and counters["up"]["held"] >= 1, counters


def _stall_then_centre(c: Cluster, stick) -> tuple[float, float, float]:
    """Drive ``move`` (its payload file ``stick``) until it moves the hand, stall its link,
    wait for a second of fresh input after the stall, centre the stick, push again. The
    daemon's status stamps of: the first status following ``move``, the first with fresh
    input after the stall, the first after the zero that no longer names ``move``."""
    def moving_since(since: float) -> float | None:
        """The stamp of the first status after ``since`` in which the daemon follows
        fresh input of ``move``."""
        return next((m["stamp"] for m in _status(c, since)
                     if m["input"]["owner"] == "move" and _age(m) < INPUT_TIMEOUT_S), None)
    assert wait_for(lambda: len(_inputs(c, "move")) >= 10, 60), _logs(c)
    write_payload(stick, MOVE)
    assert wait_for(lambda: moving_since(_inputs(c, "move")[0]["stamp"]), 60), _logs(c)
    start = moving_since(_inputs(c, "move")[0]["stamp"])
    assert start is not None
    c.input_link.stall(STALL_S, "up")
    assert wait_for(lambda: any(_age(m) > STALL_S / 2 for m in _status(c, start)), 30), _logs(c)
    late = max(m["stamp"] for m in _status(c, start) if _age(m) > STALL_S / 2)

    def fresh_since(since: float, n: int) -> list[dict]:
        """Statuses after ``since`` whose newest input is fresh by arrival and by its
        sender's stamp (the backlog drained), the first ``n``."""
        stamp_of = {m["seq"]: m["stamp"] for m in _inputs(c, "move")}
        return [m for m in _status(c, since) if _age(m) < INPUT_TIMEOUT_S and m["in_seq"] in stamp_of
                and m["stamp"] - stamp_of[m["in_seq"]] < INPUT_TIMEOUT_S][:n]
    # a second of fresh, deflected input after the stall
    assert wait_for(lambda: len(fresh_since(late, 20)) >= 20, 30), _logs(c)
    fresh_again = fresh_since(late, 1)[0]["stamp"]
    write_payload(stick, REST)
    last = _status(c, 0.0)[-1]["stamp"]
    assert wait_for(lambda: any("move" not in _rearm(m) for m in _status(c, last)), 30), _logs(c)
    centred = next(m["stamp"] for m in _status(c, last) if "move" not in _rearm(m))
    write_payload(stick, MOVE)
    assert wait_for(lambda: moving_since(centred) is not None, 30), _logs(c)
    resumed = moving_since(centred)
    assert resumed is not None
    assert wait_for(lambda: len(_status(c, resumed)) >= 20, 30), _logs(c)  # a second of it
    return start, fresh_again, centred


def _held_not_lost_and_fresh_moves(c: Cluster, stale_end: float) -> None:
    """Every input message arrived (no seq missing: the stall held them, TCP lost none),
    some of them a stall late; and every target that moved after the stall used an input
    message stamped within the input timeout of it."""
    inputs = _inputs(c, "move")
    seqs = [m["seq"] for m in inputs]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs))), "input messages lost or out of order"
    assert max(m["t"] - m["stamp"] for m in inputs) > STALL_S / 2, "no input message was held"
    stamp_of = {m["seq"]: m["stamp"] for m in inputs}
    after = _targets(c, stale_end)
    moving = [b for a, b in itertools.pairwise(after)
              if max(abs(x - y) for x, y in zip(a["pose"][:3], b["pose"][:3], strict=True)) > 1e-5]
    assert moving, "the hand did not move again after the stall"
    for t in moving:
        assert t["in_seq"] in stamp_of, t
        assert t["stamp"] - stamp_of[t["in_seq"]] <= INPUT_TIMEOUT_S + 0.01, \
            ("a target moved on a stale input", t, stamp_of[t["in_seq"]])


def test_after_a_reset_of_the_input_link_the_input_reconnects_through_it(cluster):
    """Both sides of the input's connection get an RST; its Zenoh session reconnects by
    itself (through the proxy again) and the daemon gets its input again."""
    c = cluster
    at_rest = c.start_input({"u": [0.0, 0.0, 0.0], "buttons": [0, 1, 0]}, name="reset")
    try:
        def newest_seq() -> int:
            got = _inputs(c, "reset")
            return got[-1]["seq"] if got else -1

        def daemon_has(seq: int, since: float) -> bool:
            """A status after ``since`` follows fresh input newer than ``seq`` (the only
            input sending is this one)."""
            return any(m["in_seq"] > seq and _age(m) < INPUT_TIMEOUT_S for m in _status(c, since))
        assert wait_for(lambda: newest_seq() >= 10 and daemon_has(5, _inputs(c, "reset")[0]["stamp"]), 60), \
            _logs(c)
        since = _status(c, 0.0)[-1]["stamp"]
        before = c.input_link.counters()
        assert c.input_link.reset() >= 1, before
        # the input program's session opened a new connection through the proxy ...
        assert wait_for(lambda: c.input_link.counters()["connections"] > before["connections"], 30), \
            (before, c.input_link.counters(), _logs(c))
        seq = newest_seq()
        # ... and its input, sent after the reset, reaches the daemon
        assert wait_for(lambda: daemon_has(seq + 10, since), 30), _logs(c)
    finally:
        at_rest.stop()
    counters = c.input_link.counters()
    assert counters["resets"] == before["resets"] + 1, counters


def test_a_link_must_touch_the_router_and_be_faulted_before_its_programs_start(cluster):
    c = cluster
    with pytest.raises(ValueError, match="a link is a host's to the router"):
        c.fault("runtime", "robot", LinkFault(delay_ms=5))
    with pytest.raises(RuntimeError, match="robot: programs already run there"):
        c.fault("router", "robot", LinkFault(delay_ms=5))
