"""The link fault's schedule (``sctd.deploy.linkfault``), pure: release times and drops
for a seed and a spec, without sockets or a clock; and the proxy's control requests,
in-process. The proxy moving bytes is tested on loopback in ``tests/test_linkproxy.py``
(slow) and on a cluster link in ``tests/test_linkfault_multihost.py``."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sctd.deploy.linkfault import Direction, LinkFault, Schedule
from sctd.deploy.linkproxy import LinkControl, LinkProxy, answer, parse_address, serve_control


def _releases(fault: LinkFault, arrivals: list[tuple[float, int]], name: str = "up",
              stream: int = 0) -> list[float]:
    s = Schedule(Direction(fault), name, stream)
    return [s.release(t, n) for t, n in arrivals]


ARRIVALS = [(0.001 * k, 100) for k in range(500)]  # a chunk a millisecond


def test_a_seed_and_a_spec_give_the_same_release_times_and_another_seed_others():
    f = LinkFault(delay_ms=20, jitter=0.2, seed=1)
    a, b = _releases(f, ARRIVALS), _releases(f, ARRIVALS)
    assert a == b
    assert _releases(LinkFault(delay_ms=20, jitter=0.2, seed=2), ARRIVALS) != a
    # each direction and each stream draws on its own
    assert _releases(f, ARRIVALS, "down") != a
    assert _releases(f, ARRIVALS, "up", 1) != a


@given(seed=st.integers(0, 2**31), delay=st.floats(0.0, 200.0), jitter=st.floats(0.0, 1.0),
       gaps=st.lists(st.floats(0.0, 0.05), min_size=1, max_size=200))
def test_releases_are_ordered_and_within_the_delay_and_its_jitter(seed, delay, jitter, gaps):
    """Jitter delays a chunk, it never reorders the stream: each release is within
    delay +- jitter of its arrival, or holds behind the chunk before it."""
    f = LinkFault(delay_ms=delay, jitter=jitter, seed=seed)
    t, arrivals = 0.0, []
    for g in gaps:
        t += g
        arrivals.append((t, 10))
    out = _releases(f, arrivals)
    lo, hi = (delay - jitter * delay) / 1e3, (delay + jitter * delay) / 1e3
    for k, ((t, _), r) in enumerate(zip(arrivals, out, strict=True)):
        assert r >= t + lo - 1e-9
        assert r <= t + hi + 1e-9 or (k > 0 and r == out[k - 1])
        assert k == 0 or r >= out[k - 1]


def test_jitter_spreads_the_delay_over_its_whole_width():
    f = LinkFault(delay_ms=20, jitter_ms=5, seed=3)
    arrivals = [(1.0 * k, 1) for k in range(400)]  # far apart: no chunk waits for another
    delays = [r - t for (t, _), r in zip(arrivals, _releases(f, arrivals), strict=True)]
    assert min(delays) < 0.0155 and max(delays) > 0.0245
    assert all(0.015 - 1e-9 <= d <= 0.025 + 1e-9 for d in delays)


def test_a_stall_holds_what_would_leave_within_it_and_releases_it_in_order_at_its_end():
    f = LinkFault(delay_ms=10, stalls=((1.0, 2.0),))
    arrivals = [(0.5, 1), (0.985, 1), (0.995, 1), (1.5, 1), (2.989, 1), (2.991, 1), (3.5, 1)]
    out = _releases(f, arrivals)
    assert out[0] == pytest.approx(0.51)
    assert out[1] == pytest.approx(0.995)  # left before the stall began
    assert out[2:5] == [3.0, 3.0, 3.0]  # held, released at its end (in arrival order: a queue)
    s = Schedule(Direction(f))
    held = []
    for t, n in arrivals:
        s.release(t, n)
        held.append(s.held)
    assert held == [False, False, True, True, True, False, False]
    assert out[5] == pytest.approx(3.001)  # due after the stall: not held
    assert out[6] == pytest.approx(3.51)


def test_a_stall_started_while_running_holds_like_one_in_the_spec():
    d = Direction(LinkFault(delay_ms=10))
    s = Schedule(d)
    assert s.release(0.0, 1) == pytest.approx(0.01) and not s.held
    d.stalls.append((0.5, 1.0))  # "stall now" at 0.5 s, for 1 s
    assert s.release(0.6, 1) == 1.5 and s.held
    assert d.stall_end(0.7) == 1.5 and d.stall_end(1.5) == 1.5
    assert d.stalls_begun(0.4) == 0 and d.stalls_begun(0.5) == 1


def test_a_chunk_behind_jittered_ones_is_not_counted_as_held():
    s = Schedule(Direction(LinkFault(delay_ms=10, jitter=1.0, seed=5)))
    for k in range(200):
        s.release(0.001 * k, 1)
        assert not s.held


def test_touching_stalls_are_crossed_together():
    d = Direction(LinkFault(stalls=((1.0, 1.0), (2.0, 0.5))))
    assert d.stall_end(1.2) == 2.5


def test_bandwidth_spaces_chunks_by_their_size():
    f = LinkFault(bandwidth=1000.0)  # 1000 bytes/s
    out = _releases(f, [(0.0, 100)] * 5)  # a burst of five 100-byte chunks
    assert out == pytest.approx([0.1, 0.2, 0.3, 0.4, 0.5])
    # a chunk after the link went idle is not held behind the burst
    s = Schedule(Direction(f))
    s.release(0.0, 100)
    assert s.release(5.0, 100) == pytest.approx(5.1)


def test_after_a_stall_the_backlog_drains_at_the_bandwidth():
    """A stalled link sends nothing: what it held leaves one chunk per n / bandwidth
    after the stall, not in one burst at its end."""
    f = LinkFault(bandwidth=1000.0, stalls=((1.0, 2.0),))
    out = _releases(f, [(1.0 + 0.1 * k, 100) for k in range(5)])  # within the stall
    assert out == pytest.approx([3.1, 3.2, 3.3, 3.4, 3.5])
    s = Schedule(Direction(f))
    for k in range(5):
        s.release(1.0 + 0.1 * k, 100)
        assert s.held
    assert s.release(3.45, 100) == pytest.approx(3.6)  # after the stall, behind the backlog:
    assert not s.held  # waited, but not for the stall
    # without a bandwidth the stall's end releases them all at once
    assert _releases(LinkFault(stalls=((1.0, 2.0),)), [(1.0 + 0.1 * k, 100) for k in range(5)]) == [3.0] * 5


def test_bandwidth_and_delay_add_up():
    out = _releases(LinkFault(delay_ms=50, bandwidth=1000.0), [(0.0, 100), (0.0, 100)])
    assert out == pytest.approx([0.15, 0.25])


def test_loss_drops_the_same_datagrams_for_a_seed_and_about_its_share():
    def dropped(seed: int) -> list[int]:
        s = Schedule(Direction(LinkFault(loss=0.1, seed=seed)), "up", 0)
        return [k for k in range(2000) if s.drops()]
    a = dropped(7)
    assert a == dropped(7)
    assert a != dropped(8)
    assert 150 <= len(a) <= 250  # 10 % of 2000, 4.7 standard deviations either side
    assert not any(Schedule(Direction(LinkFault())).drops() for _ in range(100))
    assert all(Schedule(Direction(LinkFault(loss=1.0))).drops() for _ in range(100))


def test_loss_draws_do_not_move_the_jitter():
    """A datagram's drop and a chunk's delay come from generators of their own, so the
    delays of a seed do not depend on the loss."""
    arrivals = ARRIVALS[:50]
    with_loss = Schedule(Direction(LinkFault(delay_ms=20, jitter=0.5, loss=0.3, seed=4)))
    out = []
    for t, n in arrivals:
        with_loss.drops()
        out.append(with_loss.release(t, n))
    assert out == _releases(LinkFault(delay_ms=20, jitter=0.5, seed=4), arrivals)


@pytest.mark.parametrize("fields, where", [
    ({"delay_ms": -1}, "LinkFault.delay_ms"),
    ({"delay_ms": float("nan")}, "LinkFault.delay_ms"),
    ({"jitter": 1.5}, "LinkFault.jitter"),
    ({"jitter": 0.1, "jitter_ms": 2}, "LinkFault.jitter, jitter_ms"),
    ({"loss": 2}, "LinkFault.loss"),
    ({"bandwidth": True}, "LinkFault.bandwidth"),
    ({"stalls": [[1.0]]}, r"LinkFault.stalls\[0\]"),
    ({"stalls": [[1.0, -2]]}, r"LinkFault.stalls\[0\].for"),
    ({"resets": ["soon"]}, r"LinkFault.resets\[0\]"),
    ({"seed": 1.5}, "LinkFault.seed"),
    ({"delay": 20}, "LinkFault.delay: unknown field"),
])
def test_bad_faults_are_refused_naming_the_field(fields, where):
    with pytest.raises(ValueError, match=where):
        LinkFault.from_dict(fields)


def test_a_fault_round_trips_through_its_dict():
    f = LinkFault(delay_ms=20, jitter=0.2, loss=0.01, stalls=((1.0, 2.0),), bandwidth=1e6,
                  resets=(5.0,), seed=9)
    assert LinkFault.from_dict(f.to_dict()) == f
    assert LinkFault.from_dict({}) == LinkFault()


def test_control_requests_that_make_no_sense_get_an_error_not_a_crash():
    with LinkProxy(("127.0.0.1", 0), ("127.0.0.1", 9)) as proxy:
        assert "op" in answer(proxy, [1, 2])["error"]
        assert "op: expected" in answer(proxy, {"op": "explode"})["error"]
        assert "LinkFault" in answer(proxy, {"op": "stall", "seconds": -1})["error"]
        assert "direction: expected" in answer(proxy, {"op": "set", "direction": "x", "fault": {}})["error"]
        assert answer(proxy, {"op": "counters"})["ok"]["connections"] == 0


def test_the_control_socket_sets_stalls_and_counts(tmp_path):
    """In-process: the proxy's control socket and its client, no connection through it."""
    import threading

    stop = threading.Event()
    with LinkProxy(("127.0.0.1", 0), ("127.0.0.1", 9)) as proxy:
        t = serve_control(proxy, tmp_path / "c.sock", stop)
        try:
            link = LinkControl(tmp_path / "c.sock")
            link.set("up", LinkFault(delay_ms=7))
            link.stall(60.0, "down")
            assert proxy.directions["up"].fault == LinkFault(delay_ms=7)
            assert proxy.directions["down"].stall_end(proxy.now()) > proxy.now() + 50
            counters = link.counters()
            assert counters["stalls"] == 1 and counters["resets"] == 0
            assert link.reset() == 0 and link.counters()["resets"] == 1
            with pytest.raises(ValueError, match=r"LinkFault\.bandwidth"):
                link.set("both", LinkFault.from_dict({"bandwidth": -5}))
        finally:
            stop.set()
            t.join(5)
    assert not (tmp_path / "c.sock").exists()


@pytest.mark.parametrize("text", ["127.0.0.1", ":80", "host:port", "h:70000"])
def test_an_address_is_host_and_port(text):
    with pytest.raises(ValueError, match="expected HOST:PORT"):
        parse_address(text)
    assert parse_address("10.0.0.1:7448") == ("10.0.0.1", 7448)
