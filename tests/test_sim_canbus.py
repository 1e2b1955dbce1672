"""Joint bus: DBC frames, CRC, counters, fault injection and detection, drive brakes."""

from __future__ import annotations

import queue
import threading
import types
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from can.interfaces import virtual as can_virtual
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd_sim.arm import SimArm
from sctd_sim.canbus import (
    CMD_BASE_ID,
    DBC_PATH,
    STATE_BASE_ID,
    STATUS_BRAKED,
    STATUS_SATURATED,
    STATUS_TIMEOUT,
    SYNC_ID,
    FastVirtualBus,
    FaultConfig,
    FaultInjectingBus,
    FrameCodec,
    FrameCrc,
    FrameGroup,
    JointBusCodecs,
    _codec_generated,
    classify,
    codegen,
    crc8,
    frame_crc,
    load_dbc,
)
from sctd_sim.canbus.crc import word_tables
from sctd_sim.canbus.frames import CLASSIC_FRAME_SLOTS
from sctd_sim.canbus.link import ACCEPTED, DUPLICATED, STALE
from sctd_sim.canbus.virtual import RxQueue

CODECS = JointBusCodecs()


@pytest.fixture(autouse=True)
def no_leaked_buses():
    """Fail a test that leaves a virtual bus open."""
    before = set(can_virtual.channels)
    yield
    leaked = set(can_virtual.channels) - before
    assert not leaked, f"virtual bus channels left open: {leaked}"


# -- DBC and codecs -----------------------------------------------------------------------
def test_dbc_defines_sync_and_one_command_and_state_frame_per_joint():
    db = load_dbc(DBC_PATH)
    ids = sorted(m.frame_id for m in db.messages)
    assert ids == sorted([SYNC_ID] + [CMD_BASE_ID + j for j in range(1, 8)]
                         + [STATE_BASE_ID + j for j in range(1, 8)])
    for m in db.messages:
        assert m.length == 8
        assert [s.name for s in m.signals[:2]] == ["CRC", "Counter"]
        assert sum(s.length for s in m.signals) <= 64
    cmd = db.get_message_by_name("JointCmd_3")
    assert {s.name for s in cmd.signals} >= {"Torque", "Position", "Velocity", "Mode"}
    state = db.get_message_by_name("JointState_3")
    assert {s.name for s in state.signals} >= {"Torque", "Position", "Velocity", "Status"}


def test_crc8_sae_j1850_check_value():
    assert crc8(b"123456789") == 0x4B
    assert isinstance(CODECS.sync.crc, FrameCrc)


@settings(max_examples=200, deadline=None)
@given(st.sampled_from([c.frame_id for c in CODECS.all]), st.binary(min_size=8, max_size=8))
def test_fast_crc_equals_reference(frame_id, data):
    assert CODECS.by_id[frame_id].crc(data) == frame_crc(frame_id, data)


def _values(codec, draw):
    vals = []
    for name in codec.signal_names:
        lo, hi = codec.limits(name)
        vals.append(draw(st.floats(lo, hi, allow_nan=False)))
    return vals


@st.composite
def frames(draw):
    codec = draw(st.sampled_from(CODECS.all))
    return codec, draw(st.integers(0, 15)), _values(codec, draw)


@settings(max_examples=300, deadline=None)
@given(frames())
def test_round_trip_every_frame_within_half_a_step(frame):
    codec, counter, values = frame
    data = codec.encode(counter, values)
    ok, c, decoded = codec.decode(data)
    assert ok and c == counter
    for name, x, y in zip(codec.signal_names, values, decoded, strict=True):
        assert abs(x - y) <= 0.5 * codec.resolution(name) * (1 + 1e-9), name


@settings(max_examples=300, deadline=None)
@given(frames())
def test_fast_codec_is_bit_identical_to_cantools(frame):
    codec, counter, values = frame
    data = codec.encode(counter, values)
    assert bytes(data) == codec.encode_cantools(counter, values)
    ok, c, fast = codec.decode(data)
    ok2, c2, slow = codec.decode_cantools(data)
    assert (ok, c) == (ok2, c2)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(frames(), st.integers(0, 7), st.integers(1, 255))
def test_any_corrupted_byte_is_detected(frame, index, flip):
    codec, counter, values = frame
    data = codec.encode(counter, values)
    data[index] ^= flip
    assert not codec.decode(data)[0]


@settings(max_examples=200, deadline=None)
@given(st.sampled_from([c.frame_id for c in CODECS.all]), st.binary(min_size=8, max_size=8))
def test_word_table_crc_equals_reference(frame_id, data):
    t1, t23, t45, t67 = word_tables()
    w23, w45, w67 = (int.from_bytes(data[k:k + 2], "little") for k in (2, 4, 6))
    crc = CODECS.by_id[frame_id].crc.const ^ t1[data[1]] ^ t23[w23] ^ t45[w45] ^ t67[w67]
    assert crc == frame_crc(frame_id, data)


@st.composite
def group_frames(draw):
    group = draw(st.sampled_from([CODECS.cmd_group, CODECS.state_group]))
    rows = [_values(codec, draw) for codec in group.codecs]
    return group, draw(st.integers(0, 15)), rows


@settings(max_examples=150, deadline=None)
@given(group_frames())
def test_frame_group_is_the_frames_one_by_one(frame):
    group, counter, rows = frame
    msgs = group.frames(2.5, counter, *zip(*rows, strict=True))
    assert [m.arbitration_id for m in msgs] == list(group.frame_ids)
    for codec, m, vals in zip(group.codecs, msgs, rows, strict=True):
        assert bytes(m.data) == codec.encode_cantools(counter, vals)  # bit for bit
        assert m.equals(codec.frame(2.5, counter, *vals))
        assert (m.timestamp, m.dlc, m.is_rx, m.channel) == (2.5, 8, False, None)
    one_by_one = [codec.decode(m.data) for codec, m in zip(group.codecs, msgs, strict=True)]
    assert group.unpack_exact(msgs, counter) == tuple(zip(*(v for _, _, v in one_by_one), strict=True))
    for names in group.subsets:
        assert group.unpacker(names)(msgs, counter) == tuple(
            tuple(v[group.signal_names.index(name)] for _, _, v in one_by_one) for name in names)


@settings(max_examples=100, deadline=None)
@given(group_frames(), st.integers(0, 6), st.integers(0, 7), st.integers(1, 255))
def test_frame_group_refuses_anything_but_the_exact_clean_group(frame, k, index, flip):
    group, counter, rows = frame
    msgs = group.frames(0.0, counter, *zip(*rows, strict=True))
    assert group.unpack_exact(msgs, (counter + 1) & 0xF) is None  # another cycle's
    assert group.unpack_exact(msgs[:-1], counter) is None  # one missing
    assert group.unpack_exact([*msgs, msgs[-1]], counter) is None  # one more
    assert group.unpack_exact(msgs[1:] + msgs[:1], counter) is None  # out of order
    corrupt = list(msgs)
    data = bytearray(msgs[k].data)
    data[index] ^= flip
    corrupt[k] = can.Message(arbitration_id=msgs[k].arbitration_id, data=data,
                             is_extended_id=False)
    assert group.unpack_exact(corrupt, counter) is None
    corrupt[k] = can.Message(arbitration_id=msgs[k].arbitration_id, data=msgs[k].data[:7],
                             is_extended_id=False)
    assert group.unpack_exact(corrupt, counter) is None


def test_generated_frames_set_every_message_slot():
    slots = {"arbitration_id", "timestamp", "data", *CLASSIC_FRAME_SLOTS}
    assert slots == set(can.Message.__slots__) - {"__weakref__"}
    m = CODECS.state_group.frames(1.0, 3, *([0] * 7 for _ in range(4)))[0]
    assert all(hasattr(m, name) for name in slots)
    assert m.equals(can.Message(timestamp=1.0, arbitration_id=m.arbitration_id, data=m.data,
                                is_extended_id=False, is_rx=False))


def test_frame_group_needs_one_layout():
    with pytest.raises(ValueError, match="one payload layout"):
        FrameGroup([CODECS.cmd[0], CODECS.state[0]])
    with pytest.raises(ValueError, match="no signals"):
        CODECS.cmd_group.unpacker(["Torque", "Nope"])
    with pytest.raises(ValueError, match="no generated code"):
        CODECS.cmd_group.unpacker(["Velocity", "Mode"])
    assert CODECS.cmd_group.subsets == (CODECS.cmd_group.signal_names, ("Mode", "Torque"))


def test_generated_codec_is_what_the_dbc_gives():
    """The checked-in module is byte for byte what the generator writes from the DBC."""
    assert Path(_codec_generated.__file__).read_text() == codegen.module_source(DBC_PATH)
    assert codegen.main(["--check"]) == 0


def test_a_layout_without_generated_code_is_refused():
    msg = cantools.database.load_file(str(DBC_PATH)).get_message_by_name("JointCmd_1")
    msg.get_signal_by_name("Torque").scale = 0.02  # a DBC edited without regenerating
    with pytest.raises(ValueError, match="JointCmd_1: payload layout not in the generated codec"):
        FrameCodec(msg)
    with pytest.raises(ValueError, match="not a group of the generated codec"):
        FrameGroup(CODECS.cmd[1:])


def test_rx_queue_wakes_a_blocked_receiver_and_drains_in_order():
    rx = RxQueue()
    with pytest.raises(queue.Empty):
        rx.get(timeout=0.01)
    threading.Timer(0.05, rx.put, args=("late",)).start()
    assert rx.get(timeout=5.0) == "late"
    rx.put_batch(["a", "b"])
    rx.put("c")
    assert rx.qsize() == 3 and rx.get_nowait() == "a"
    assert rx.drain() == ["b", "c"] and rx.empty()


def test_out_of_range_values_saturate():
    codec = CODECS.cmd[0]
    _ok, _c, vals = codec.decode(codec.encode(0, (1, 1e6, -1e6, 0.0)))
    assert vals[1] == pytest.approx(codec.limits("Torque")[1])
    assert vals[2] == pytest.approx(codec.limits("Position")[0])


def test_frame_with_wrong_length_is_rejected():
    assert CODECS.state[0].decode(b"\x00" * 7)[0] is False


def test_classify_counters():
    assert classify(5, 4, 5, False) == (ACCEPTED, 0)
    assert classify(7, 4, 7, False) == (ACCEPTED, 2)  # two frames lost
    assert classify(5, 5, 5, True) == (DUPLICATED, 0)
    assert classify(5, 5, 6, False) == (DUPLICATED, 0)  # a late duplicate
    assert classify(3, 4, 5, False) == (STALE, 0)
    assert classify(0, 15, 0, False) == (ACCEPTED, 0)  # wrap-around
    assert classify(1, None, None, False) == (ACCEPTED, 0)
    assert classify(2, 15, None, False) == (ACCEPTED, 2)
    assert classify(10, 15, None, False) == (STALE, 0)


# -- the bus in use ---------------------------------------------------------------------
def test_clean_bus_has_no_faults_and_a_plain_virtual_bus_sees_every_frame():
    with SimArm() as sim:
        watcher = can.Bus(interface="virtual", channel=sim.channel)
        try:
            batches = []
            sim.on_frames.append(batches.append)
            sim.run(0.1)
            seen = []
            while (m := watcher.recv(0)) is not None:
                seen.append(m)
        finally:
            watcher.shutdown()
        assert len(seen) == 100 * 15
        assert all(len(b) == 15 for b in batches) and len(batches) == 100
        assert [m.arbitration_id for m in seen[:15]] == (
            [SYNC_ID] + [CMD_BASE_ID + j for j in range(1, 8)]
            + [STATE_BASE_ID + j for j in range(1, 8)])
        db = load_dbc()
        decoded = db.decode_message(seen[-1].arbitration_id, bytes(seen[-1].data))
        assert decoded["Position"] == pytest.approx(sim.q[6], abs=1e-5)
        stats = sim.link_stats()
        for side in ("controller_rx", "drives_rx"):
            counts = stats[side]
            assert counts["accepted"] == counts["received"] > 0
            assert all(counts[k] == 0 for k in ("corrupted", "duplicated", "stale", "lost",
                                                "missing", "unknown", "tx_errors")), counts
        assert stats["brake_events"] == 0


def test_frames_sent_from_another_virtual_bus_reach_the_drives():
    # An external node can inject frames; a frame with a bad CRC is counted.
    with SimArm() as sim:
        node = can.Bus(interface="virtual", channel=sim.channel)
        try:
            sim.step()
            node.send(can.Message(arbitration_id=CMD_BASE_ID + 1, data=bytes(8),
                                  is_extended_id=False))
            node.send(can.Message(arbitration_id=0x7FF, data=bytes(8), is_extended_id=False))
            sim.step()
        finally:
            node.shutdown()
        assert sim.drives.stats.corrupted == 1
        assert sim.drives.stats.unknown == 1


def _frame_by_frame(sim):
    """Turn off both ends' clean-cycle shortcuts: every cycle takes the general path."""
    sim.master._state_group = types.SimpleNamespace(unpack_exact=lambda frames, counter: None)
    sim.drives._unpack_cmds = lambda frames, counter: None
    each = sim.drives._receive_each

    def receive_each(frames, t):
        each(frames, t)
        sim.drives._running_t = None  # and output()'s quick case

    sim.drives._receive_each = receive_each


@pytest.mark.parametrize("faults", [
    None,
    dict(drop_rate=0.1, corrupt_rate=0.05, duplicate_rate=0.05, delay=0.002, delay_rate=0.05,
         rx=True, seed=13),
    dict(drop_rate=0.3, tx=False, rx=True, seed=14),
])
def test_clean_cycle_shortcuts_change_nothing(faults):
    runs = []
    for shortcut in (True, False):
        with SimArm(faults=None if faults is None else FaultConfig(**faults)) as sim:
            if not shortcut:
                _frame_by_frame(sim)
            batches: list = []
            sim.on_frames.append(
                lambda b, out=batches: out.append([(m.arbitration_id, bytes(m.data)) for m in b]))
            T = sim.T_world_ee  # a quarter turn away: the wrist torques saturate a while
            T[:3, :3] = T[:3, :3] @ np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
            T[:3, 3] += [0.03, -0.02, 0.01]
            for k in range(400):
                if sim.faults is not None and k in (200, 230):
                    sim.faults.set_bus_off(k == 200)
                sim.set_target(T, stamp=sim.t)
                sim.step()
            runs.append((sim.link_stats(), sim.q, batches, sim.master.age.copy(),
                         sim.master.status.copy(), sim.drives.status.copy()))
    (stats, q, batches, age, m_status, d_status), reference = runs
    assert stats == reference[0]
    np.testing.assert_array_equal(q, reference[1])
    assert batches == reference[2]
    np.testing.assert_array_equal(age, reference[3])
    np.testing.assert_array_equal(m_status, reference[4])
    np.testing.assert_array_equal(d_status, reference[5])
    if faults is None:
        assert stats["controller_rx"]["accepted"] == 400 * 7
        assert any(f[1][1] >> 4 & STATUS_SATURATED for b in batches for f in b[8:])


def run_faulty(config, seconds=0.3, **kwargs):
    with SimArm(faults=config, **kwargs) as sim:
        p0 = sim.T_world_ee[:3, 3]
        sim.run(seconds)
        return sim.link_stats(), np.linalg.norm(sim.T_world_ee[:3, 3] - p0)


def test_dropped_commands_are_counted_as_lost_and_missing():
    stats, drift = run_faulty(FaultConfig(drop_rate=0.05, seed=1))
    d = stats["drives_rx"]
    assert stats["injected"]["dropped"] > 0
    assert d["lost"] > 0 and d["missing"] > 0
    assert d["corrupted"] == d["duplicated"] == d["stale"] == 0
    assert drift < 1e-3


def test_dropped_states_are_counted_by_the_controller():
    stats, _ = run_faulty(FaultConfig(drop_rate=0.05, tx=False, rx=True, seed=2))
    c = stats["controller_rx"]
    assert c["lost"] > 0 and c["missing"] > 0
    assert c["corrupted"] == c["duplicated"] == c["stale"] == 0


def test_delayed_frames_are_stale():
    stats, drift = run_faulty(FaultConfig(delay=0.0025, delay_rate=0.05, seed=3))
    d = stats["drives_rx"]
    assert stats["injected"]["delayed"] > 0
    assert d["stale"] > 0
    assert drift < 1e-3


def test_constant_latency_makes_every_state_stale():
    stats, _ = run_faulty(FaultConfig(delay=0.0015, delay_rate=1.0, tx=False, rx=True, seed=4),
                          seconds=0.05)
    c = stats["controller_rx"]
    assert c["accepted"] == 0 and c["stale"] > 0


def test_duplicates_are_detected_one_for_one():
    stats, _ = run_faulty(FaultConfig(duplicate_rate=0.1, seed=5))
    assert stats["drives_rx"]["duplicated"] == stats["injected"]["duplicated"] > 0
    assert stats["drives_rx"]["lost"] == 0


def test_corrupted_frames_are_detected_one_for_one():
    stats, _ = run_faulty(FaultConfig(corrupt_rate=0.05, seed=6))
    assert stats["drives_rx"]["corrupted"] == stats["injected"]["corrupted"] > 0
    stats, _ = run_faulty(FaultConfig(corrupt_rate=0.05, tx=False, rx=True, seed=7))
    assert stats["controller_rx"]["corrupted"] == stats["injected"]["corrupted"] > 0


def test_fault_injection_is_repeatable():
    a, _ = run_faulty(FaultConfig(drop_rate=0.1, corrupt_rate=0.1, seed=8), seconds=0.1)
    b, _ = run_faulty(FaultConfig(drop_rate=0.1, corrupt_rate=0.1, seed=8), seconds=0.1)
    assert a == b


def test_missing_commands_make_the_drives_brake_and_report_it():
    config = FaultConfig(seed=9)
    with SimArm(faults=config, drive_timeout=0.01) as sim:
        sim.run(0.1)
        assert not sim.drives.braked.any()
        config.drop_rate = 1.0  # the controller's commands stop reaching the drives
        sim.run(0.005)
        assert not sim.drives.braked.any()  # within the timeout: still running
        sim.run(0.02)
        assert sim.drives.braked.all()
        assert sim.drives.brake_events == 7
        # the state frames still arrive and say so
        assert np.all(sim.master.status & STATUS_BRAKED)
        assert np.all(sim.master.status & STATUS_TIMEOUT)
        q_braked = sim.q
        sim.run(0.2)
        np.testing.assert_array_equal(sim.q, q_braked)  # brakes hold the position
        config.drop_rate = 0.0
        sim.run(0.05)
        assert not sim.drives.braked.any()
        assert not np.any(sim.master.status & STATUS_BRAKED)


def test_bus_off_refuses_frames_and_the_arm_brakes_in_place():
    with SimArm(faults=FaultConfig(seed=10)) as sim:
        sim.run(0.1)
        p0 = sim.T_world_ee[:3, 3]
        sim.faults.set_bus_off(True)
        assert sim.faults.state == can.BusState.ERROR
        sim.run(0.1)
        stats = sim.link_stats()
        assert stats["controller_rx"]["tx_errors"] == 100
        assert stats["controller_rx"]["missing"] >= 7 * 100
        assert sim.drives.braked.all()
        assert np.linalg.norm(sim.T_world_ee[:3, 3] - p0) < 1e-3
        sim.faults.set_bus_off(False)
        sim.run(0.1)
        assert not sim.drives.braked.any()
        assert sim.master.fresh.all()


def test_fault_wrapper_is_a_python_can_bus():
    inner = FastVirtualBus(channel="sctd-test-wrapper")
    peer = can.Bus(interface="virtual", channel="sctd-test-wrapper")
    with FaultInjectingBus(inner, FaultConfig(rx=True, tx=False)) as bus:
        peer.send(can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False))
        m = bus.recv(0.5)
        assert m is not None and m.arbitration_id == 0x123
        bus.send(can.Message(arbitration_id=0x124, data=b"\x03", is_extended_id=False))
        assert peer.recv(0.5).arbitration_id == 0x124
    peer.shutdown()


def test_fault_config_is_validated():
    with pytest.raises(ValueError, match="drop_rate"):
        FaultConfig(drop_rate=1.5)
    with pytest.raises(ValueError, match="delay"):
        FaultConfig(delay=-1.0)
