"""The daemon's parts, each on its own: the swap of a skill between two ticks
(:class:`SkillSwap`; with a skill set, of a member), the tick statistics
(:class:`TickStats`) and the status map (:class:`DaemonStatus`). The loop they serve is
tested by tests/test_driver.py, the daemon they make up by the end-to-end tests."""

from __future__ import annotations

import logging
import os
import threading
import time
from collections import deque
from pathlib import Path

import pytest

from sctd.runtime import bundles
from sctd.runtime import swap as swap_module
from sctd.runtime.controller import RuntimeConfig
from sctd.runtime.driver import TickDriver
from sctd.runtime.ingress import Ingress
from sctd.runtime.loop import TickLoop
from sctd.runtime.sets import goal_set
from sctd.runtime.status import RECENT, DaemonStatus, TickStats
from sctd.runtime.swap import SkillSwap
from sctd.skill import Bundle, SkillError, bundle_from_file, load_skill, skill_from_bundle
from sctd.skill.skillset import load_skill_set
from sctd.timing import Ticker, threads_niced
from sctd.wire import Keys, codec

ROOT = Path(__file__).resolve().parents[1]
KEYS = Keys()


class _Sub:
    def __init__(self, key: str):
        self.key, self.ring, self.live = key, deque(), True

    def try_recv(self):
        return self.ring.popleft() if self.ring else None

    def undeclare(self):
        self.live = False


class _Session:
    """Subscriptions as the ingress declares them (nothing ever arrives)."""

    def __init__(self):
        self.subs: list[_Sub] = []

    def declare_subscriber(self, key, handler):
        self.subs.append(_Sub(key))
        return self.subs[-1]

    def live(self, key: str) -> bool:
        return any(s.live for s in self.subs if s.key == key)


@pytest.fixture(scope="module")
def skills():
    return load_skill(ROOT / "skills" / "pour.yaml"), load_skill(ROOT / "skills" / "drawer.yaml")


def _running(skill):
    """A driver on ``skill``, its ingress on a fake session, and the swap into them."""
    session = _Session()
    driver = TickDriver(skill, RuntimeConfig())
    swap = SkillSwap(driver)
    swap.ingress = Ingress(session, KEYS, driver)  # type: ignore[arg-type]
    return session, driver, swap


# --- the swap ------------------------------------------------------------------------------

def test_a_swap_lands_between_two_ticks_and_retires_the_old_object_ring(skills):
    pour, drawer = skills
    session, driver, swap = _running(pour)
    result: list = []
    t = threading.Thread(target=lambda: result.append(swap.swap(drawer)))
    t.start()
    now = 0.0
    while t.is_alive():  # the tick: the mailbox is read ahead of every tick
        if swap.pending is not None:
            swap.install(now)
        now += 1e-3
        t.join(1e-3)
    assert result == [drawer.start] and driver.skill is drawer and driver.engine.state == drawer.start
    assert swap.pending is None
    assert set(swap.ingress.objects) == {"drawer_handle"}
    assert session.live(KEYS.objects("drawer_handle")) and not session.live(KEYS.objects("mug"))


def test_a_swap_is_refused_unless_the_daemon_runs(skills):
    pour, drawer = skills
    driver = TickDriver(pour, RuntimeConfig())
    with pytest.raises(SkillError, match="the daemon is not running"):
        SkillSwap(driver).swap(drawer)  # no ingress: not running
    _, driver, swap = _running(pour)
    swap.stop_event.set()
    with pytest.raises(SkillError, match="the daemon is not running"):
        swap.swap(drawer)
    assert driver.skill is pour


def test_a_swap_the_tick_never_takes_is_withdrawn_and_its_ring_closed(skills, monkeypatch):
    pour, drawer = skills
    monkeypatch.setattr(swap_module, "BOUNDARY_WAIT", 0.2)
    session, driver, swap = _running(pour)
    with pytest.raises(SkillError, match=r"did not reach a tick boundary in 0\.2 s"):
        swap.swap(drawer)
    assert swap.pending is None and driver.skill is pour
    assert not session.live(KEYS.objects("drawer_handle")) and session.live(KEYS.objects("mug"))
    swap.install(0.0)  # a tick after it: nothing to install
    assert driver.skill is pour


def test_the_summary_is_of_the_running_skill_and_refusals_are_counted(skills):
    pour, _ = skills
    _, driver, swap = _running(pour)
    assert swap.summary()["name"] == pour.name and swap.summary()["state"] == driver.engine.state
    swap.refuse("bundle.zip: too large")
    swap.refuse("x.yaml: states: missing")
    assert swap.refused == 2
    status = DaemonStatus(driver, TickStats(0.0, driver.engine.state, 0.1), swap)
    assert status.map(Ticker(1e-3), 0.0, 0.0)["counters"]["swaps_refused"] == 2


# --- the statistics and the status -------------------------------------------------------

def test_tick_stats_keep_the_windows_maximum_and_log_state_changes(caplog):
    stats = TickStats(10.0, "carry", status_period=0.1)
    with caplog.at_level(logging.INFO, logger="sctd.run"):
        stats.account(1e-5, 2e-4, "carry")
        stats.account(3e-5, 1e-4, "pour")
    assert "state carry -> pour" in caplog.text and stats.state == "pour"
    assert stats.lateness.n == stats.compute.n == 2 and stats.compute_max == 2e-4
    stats.roll_recent(10.0 + RECENT / 2)
    assert stats.recent is None  # not a whole window yet
    stats.roll_recent(10.0 + RECENT)
    assert stats.recent is not None and stats.recent["compute"]["n"] == 2
    stats.next_window(11.0, targets=7)
    assert (stats.window_start, stats.next_status, stats.window_targets, stats.compute_max) == \
        (11.0, pytest.approx(11.1), 7, 0.0)
    stats.account(1e-5, 5e-5, "pour")
    stats.roll_recent(11.0 + RECENT / 2)
    assert stats.recent["compute"]["n"] == 2  # the last whole window's, until the next one


def test_the_status_map_has_every_key_and_the_windows_target_rate(skills):
    pour, _ = skills
    driver = TickDriver(pour, RuntimeConfig())
    stats = TickStats(0.0, driver.engine.state, status_period=0.25)
    status = DaemonStatus(driver, stats, SkillSwap(driver), realtime=True)
    ticker = Ticker(1e-3)
    driver.target_seq = 50  # 50 targets in the first half second
    first = status.close_window(ticker, 0.5)
    assert set(first) == {
        "stamp", "skill", "skill_name", "state", "finished", "stuck", "region", "mode", "mode_button", "rate",
        "realtime", "io_nice",
        "ticks", "late_ticks", "skipped_ticks", "long_drains", "targets", "target_rate", "lateness_ms",
        "compute_ms", "publish_ms", "compute_max_window_ms", "recent_ms", "input_age",
        "state_age", "state_delay_ms", "input_delay_ms", "robot_fault", "object", "object_age", "objects",
        "in_seq", "input", "gripper", "vf_scale", "constraints", "dropped", "counters"}
    assert set(first["gripper"]) == {"commands", "messages", "cmd", "action", "source", "in_device",
                                     "reading", "reading_age", "holding", "presses", "ignored_presses",
                                     "cancelled"}
    assert first["gripper"]["commands"] == 0 and first["gripper"]["cmd"] is None
    assert first["region"] is None  # (the shipped pour states no region)
    assert first["mode_button"] is None  # (nor a button transition: the mode button does nothing)
    assert (first["targets"], first["target_rate"], first["realtime"]) == (50, 100.0, True)
    assert first["io_nice"] == 0  # (not given: the session's threads at the daemon's nice)
    assert first["publish_ms"] is None and first["mode"] == "waiting"
    assert stats.next_status == 0.75 and stats.window_targets == 50
    driver.target_seq = 60  # 10 more in the next 0.25 s
    assert status.close_window(ticker, 0.75)["target_rate"] == 40.0
    assert status.map(ticker, 0.75, 0.0)["target_rate"] is None  # the final statistics


def test_the_status_says_how_late_the_newest_state_and_input_arrived_by_their_stamps(skills):
    """``state_delay_ms`` and ``input_delay_ms``: from each newest message's stamp (its
    sender's clock) to its arrival, the time since it arrived taken off: the link's delay,
    which the person's panel tells when it is long (docs/multihost.md)."""
    pour, _ = skills
    driver = TickDriver(pour, RuntimeConfig(stamp_check=False))
    status = DaemonStatus(driver, TickStats(0.0, driver.engine.state, 0.1), SkillSwap(driver))
    empty = status.map(Ticker(1e-3), 0.0, 0.0)
    assert empty["state_delay_ms"] is None and empty["input_delay_ms"] is None
    sent = 1_000_000.0  # the senders' stamps (their clock); the daemon's is the status' own stamp
    driver.take_state(codec.StateMsg(1, sent, HAND, None), 10.0)
    driver.take_input("pad", codec.InputMsg(1, sent + 0.5, (0.0, 0.0, 0.0), (0, 1, 0, 1), False), 10.2)
    got = status.map(Ticker(1e-3), 10.25, 0.0)
    # at 10.25 the state had arrived 0.25 s before, the input 0.05 s before
    assert got["state_delay_ms"] == pytest.approx(1e3 * (got["stamp"] - sent - 0.25), abs=0.051)
    assert got["input_delay_ms"] == pytest.approx(1e3 * (got["stamp"] - sent - 0.5 - 0.05), abs=0.051)


def test_the_status_says_how_often_each_constraint_acted_in_its_window(skills):
    """``status.constraints``: the engine's counts since the last window closed, or
    since the active state was entered when that was later (a new engine after a swap
    counts from its start)."""
    pour, _ = skills
    driver = TickDriver(pour, RuntimeConfig())
    status = DaemonStatus(driver, TickStats(0.0, driver.engine.state, status_period=0.25), SkillSwap(driver))
    ticker, eng = Ticker(1e-3), driver.controller.engine

    def window(t: float) -> tuple:
        got = status.close_window(ticker, t)["constraints"]
        return got["state"], got["commands"], got["acted"]
    eng.commands, eng.acted = 10, [0, 3]
    assert window(0.25) == ("carry", 10, [0, 3])
    eng.commands, eng.acted = 25, [1, 10]
    assert window(0.5) == ("carry", 15, [1, 7])
    eng.reset(0.6, "pour")
    eng.commands, eng.acted = 4, [0, 4]
    assert window(0.75) == ("pour", 4, [0, 4])
    driver.controller.engine = type(eng)(pour)  # a swap: a new engine, counting from 0
    assert window(1.0) == ("carry", 0, [0, 0])


# --- a skill set -----------------------------------------------------------------------------

KITCHEN = ROOT / "skills" / "sets" / "kitchen.yaml"
HAND = [0.35, 0.25, 0.90, 0.0, 0.0, 0.0, 1.0]


@pytest.fixture(scope="module")
def kitchen():
    return load_skill_set(KITCHEN)


def _running_set(spec):
    """A driver on the set ``spec``, its ingress on a fake session, and the swap."""
    session = _Session()
    driver = TickDriver(None, RuntimeConfig(stamp_check=False), goals=goal_set(spec))
    swap = SkillSwap(driver, set_name=spec.name)
    swap.ingress = Ingress(session, KEYS, driver)  # type: ignore[arg-type]
    return session, driver, swap


def _swap_in(swap, skill, member=None):
    """``swap.answer(skill, member)`` on a thread of its own, installed by this (tick)
    thread; its answer."""
    result: list = []
    t = threading.Thread(target=lambda: result.append(swap.answer(skill, member)))
    t.start()
    now = 0.0
    while t.is_alive():
        if swap.pending is not None:
            swap.install(now)
        now += 1e-3
        t.join(1e-3)
    assert result, "the swap raised"
    return result[0]


def _variant(path: Path, description: str):
    """The skill of ``path`` with another description: the same name, another id."""
    b = bundle_from_file(path)
    text = b.yaml_text.replace("\ndescription:", f"\ndescription: {description}", 1)
    return skill_from_bundle(Bundle(b.name, text, b.files))


def test_a_set_reads_every_members_object_and_its_status_and_summary_say_so(kitchen):
    session, driver, swap = _running_set(kitchen)
    assert set(swap.ingress.objects) == {"drawer_handle", "door_handle", "light_switch"}
    assert all(session.live(KEYS.objects(n)) for n in swap.ingress.objects)
    status = DaemonStatus(driver, TickStats(0.0, driver.engine.state, 0.1), swap).map(Ticker(1e-3), 0.0, 0.0)
    goals = status["goals"]
    assert goals["name"] == "kitchen" and goals["engaged"] == "teleop" and goals["teleop"] == "teleop"
    assert goals["objects"] == {"drawer": "drawer_handle", "cabinet-vf": "door_handle",
                                "light_switch-vf": "light_switch"}
    assert status["skill"] == kitchen.teleop.id and status["skill_name"] == "teleop"
    summary = swap.summary()
    assert summary["id"] == kitchen.teleop.id and summary["state"] == "translate"
    assert summary["set"]["name"] == "kitchen" and summary["set"]["engaged"] == "teleop"
    assert [m["id"] for m in summary["set"]["members"]] == [m.skill.id for m in kitchen.members]
    assert summary["set"]["teleop"] == {"id": kitchen.teleop.id, "name": "teleop", "object": "world"}
    assert set(swap.in_use()) == {kitchen.teleop.id, *(m.skill.id for m in kitchen.members)}
    single = TickDriver(kitchen.members[0].skill, RuntimeConfig())
    assert "goals" not in DaemonStatus(single, TickStats(0.0, "reach", 0.1), SkillSwap(single)).map(
        Ticker(1e-3), 0.0, 0.0)


def test_a_swap_into_a_set_replaces_the_member_it_names_and_its_object_ring(kitchen):
    session, driver, swap = _running_set(kitchen)
    drawer_vf = load_skill(ROOT / "skills" / "drawer-vf.yaml")
    got = _swap_in(swap, drawer_vf, "light_switch-vf")
    assert got["member"] == "light_switch-vf" and got["state"] == drawer_vf.start
    assert drawer_vf.id in got["in_use"] and kitchen.members[2].skill.id not in got["in_use"]
    assert [m.name for m in driver.goals.members] == ["drawer", "cabinet-vf", "drawer-vf"]
    assert driver.skill.name == "teleop"  # nothing engaged: the swap changes no running skill
    assert set(swap.ingress.objects) == {"drawer_handle", "door_handle"}
    assert not session.live(KEYS.objects("light_switch"))
    # engage cabinet-vf by choose (the drawer's handle is not seen: it is skipped)
    driver.take_state(codec.StateMsg(1, 0.0, HAND, None), 0.0)
    driver.take_object("door_handle", codec.ObjectMsg(1, 0.0, [0.6, -0.2, 0.7, 0, 0, 0, 1]), 0.0)
    driver.take_input("pad", codec.InputMsg(1, 0.0, (0.0, 0.0, 0.0), (0, 1, 0, 1), False), 0.0)
    driver.tick(0.0, 0.0)
    assert driver.skill.name == "cabinet-vf"
    # the engaged member, replaced by a skill of its name (no member named): it runs now
    cabinet2 = _variant(ROOT / "skills" / "cabinet-vf.yaml", "Relearned.")
    got = _swap_in(swap, cabinet2)
    assert got["member"] == "cabinet-vf" and driver.skill is cabinet2 and got["state"] == "default"
    assert swap.summary()["id"] == cabinet2.id and swap.summary()["set"]["engaged"] == "cabinet-vf"
    assert driver.counters.swaps == 2


def test_a_swap_that_does_not_fit_the_set_is_refused_and_changes_nothing(kitchen, tmp_path):
    _, driver, swap = _running_set(kitchen)
    pour, drawer = load_skill(ROOT / "skills" / "pour.yaml"), kitchen.members[0].skill
    text = (ROOT / "skills" / "teleop.yaml").read_text().replace("name: teleop", "name: chooser").replace(
        "object: world", "object: mug")
    chooser = skill_from_bundle(Bundle("chooser.yaml", text.replace("button: 0}", "button: 3}"), {}))
    for skill, member, problem in [
            (pour, None, "'pour' is no member of the running skill set (members: drawer, cabinet-vf, "
                         "light_switch-vf): name the member it replaces (skill/swap?member=NAME)"),
            (pour, "nope", "member 'nope': no such member"),
            (drawer, "cabinet-vf", "'drawer' is the name of another skill of the running set"),
            (kitchen.teleop, "drawer", "'teleop' is the name of another skill"),
            (skill_from_bundle(Bundle("w.yaml", text.replace("object: mug", "object: world"), {})), "drawer",
             "w.yaml: object: a member of a skill set is tied to its task object"),
            (chooser, "drawer", "chooser.yaml: fsm.transitions[0].button: button 3 is the skill set's "
                                "choose button")]:
        with pytest.raises(SkillError) as e:
            swap.swap(skill, member)
        assert problem in str(e.value), str(e.value)
    assert swap.pending is None
    assert [m.skill for m in driver.goals.members] == [m.skill for m in kitchen.members]
    _, _, single = _running(pour)
    with pytest.raises(SkillError, match="runs one skill, not a skill set: swap without naming a member"):
        single.swap(drawer, "drawer")


def test_a_sets_bundles_stay_kept_across_swaps(tmp_path):
    """The pinned ids (a running set's skills) are never dropped; the others keep the
    newest :data:`bundles.KEEP`."""
    pinned = [f"p{i}" for i in range(5)]
    for sid in pinned:
        bundles.keep(tmp_path, sid, b"x", pinned=pinned)
    for k in range(6):
        bundles.keep(tmp_path, f"s{k}", b"y", pinned=pinned)
    kept = sorted(p.stem for p in tmp_path.glob("*.bundle"))
    assert kept == sorted([*pinned, "s2", "s3", "s4", "s5"])
    bundles.keep(tmp_path, "s6", b"y")  # a single skill's swap: nothing pinned
    assert len(list(tmp_path.glob("*.bundle"))) == bundles.KEEP


def _nice_of_a_new_thread() -> int:
    seen: list[int] = []
    t = threading.Thread(target=lambda: seen.append(os.getpriority(os.PRIO_PROCESS, 0)))  # its own
    t.start()
    t.join()
    return seen[0]


def test_threads_started_in_the_block_inherit_its_nice_and_the_caller_gets_its_own_back():
    """How the daemon's Zenoh threads get their nice (``--io-nice``): a thread started
    inside the block (as the session's are, by ``zenoh.open``) keeps the block's nice
    after it; the calling thread and threads started after get the caller's own. Raised
    here (allowed to anyone), lowered as the daemon does (this runs as root, as CI does)."""
    own = os.getpriority(os.PRIO_PROCESS, 0)
    for nice in (own + 3, own - 3):
        # (without the privilege a lower nice is refused: the block runs at the caller's)
        want = nice if nice > own or os.geteuid() == 0 else own
        with threads_niced(nice) as got:
            inside = _nice_of_a_new_thread()
            caller = os.getpriority(os.PRIO_PROCESS, 0)
        assert (got, inside, caller) == (want, want, want)
        assert os.getpriority(os.PRIO_PROCESS, 0) == own and _nice_of_a_new_thread() == own


def test_a_refused_or_zero_nice_changes_nothing_and_says_the_nice_in_force(monkeypatch):
    own = os.getpriority(os.PRIO_PROCESS, 0)
    with threads_niced(0) as got:
        assert got == own and _nice_of_a_new_thread() == own

    def refuse(*_args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "setpriority", refuse)
    with threads_niced(own - 5) as got:
        assert got == own and _nice_of_a_new_thread() == own
    assert os.getpriority(os.PRIO_PROCESS, 0) == own


class _SlowDrains:
    """An ingress whose drain takes ``slow`` s every ``every``-th tick (and no time
    otherwise): the tick loop's own count of long drains must see each of those."""

    def __init__(self, every: int, slow: float):
        self.every, self.slow, self.drains, self.slow_drains, self.trash = every, slow, 0, 0, []

    def drain(self, now: float) -> None:
        self.drains += 1
        if self.drains % self.every == 0:
            self.slow_drains += 1
            end = time.monotonic() + self.slow
            while time.monotonic() < end:
                pass

    def after_tick(self) -> None:
        pass


def test_the_tick_loop_counts_each_drain_that_runs_past_its_allowance(skills):
    """``status.long_drains``: a drain 2 ms long (every 25th tick) takes more than the
    spin (0.1 ms) beyond the drain's tracked 95th percentile, whatever that is (at most
    0.25 ms): each is counted, on the loop's own count of drains."""
    pour, _ = skills
    driver = TickDriver(pour, RuntimeConfig())
    stats = TickStats(time.monotonic(), driver.engine.state, status_period=0.1)
    swap = SkillSwap(driver)
    status = DaemonStatus(driver, stats, swap)
    ingress = _SlowDrains(every=25, slow=2e-3)
    sent: list = []
    loop = TickLoop(driver, ingress, swap, sent.append)  # type: ignore[arg-type]
    ticker = Ticker(1e-3, spin=1e-4)
    loop.run(ticker, status, threading.Event(), end=time.monotonic() + 0.4)
    assert ingress.slow_drains >= 5, ingress.drains
    assert stats.long_drains >= ingress.slow_drains
    assert status.map(ticker, time.monotonic(), 0.0)["long_drains"] == stats.long_drains
    assert any(isinstance(m, dict) and "long_drains" in m for m in sent)  # in the status maps sent
