"""The python-can interface plugin ``sctd`` (CAN over Zenoh): payload codec, two buses in
one process, and python-can's own logger watching a running ``sctd sim`` from another
process; frames sent from outside reach the simulator's bus."""

from __future__ import annotations

import re
import signal

import can
import msgpack
import pytest

from sctd.wire import Keys
from sctd.wire.session import open_session
from sctd_sim.canbus.zenoh_interface import (
    FrameDecodeError,
    ZenohBus,
    can_key,
    decode_frames,
    encode_frames,
)
from tests.conftest import Proc, free_port, port_is_free, sctd, wait_for


def test_entry_point_is_registered():
    from can.interfaces import BACKENDS

    assert BACKENDS["sctd"] == ("sctd_sim.canbus.zenoh_interface", "ZenohBus")


def test_frames_round_trip_and_bad_payloads():
    msgs = [can.Message(timestamp=1.5, arbitration_id=0x181, is_extended_id=False, data=bytes(range(8))),
            can.Message(timestamp=2.0, arbitration_id=0x1ABCDEF, is_extended_id=True, data=b"\x01")]
    back = decode_frames(encode_frames(msgs))
    assert [m.equals(b, timestamp_delta=None, check_channel=False, check_direction=False)
            for m, b in zip(msgs, back, strict=True)] == [True, True]
    assert msgpack.unpackb(encode_frames(msgs[:1])) == {"v": 1, "frames": [[1.5, 0x181, False, 8,
                                                                          bytes(range(8))]]}

    def framed(*frames):
        return msgpack.packb({"v": 1, "frames": list(frames)})

    for bad in (b"\xc1", msgpack.packb({"a": 1}), msgpack.packb([[0.0, 0x181, False, 8, bytes(8)]]),
                framed([0.0, 0x181, False, 2, b"\x00"]), framed([0.0, 0x900, False, 0, b""]),
                framed([0.0, 1, False, 9, bytes(9)])):
        with pytest.raises(FrameDecodeError):
            decode_frames(bad)
    with pytest.raises(ValueError):
        can_key("a/b")


def test_two_buses_talk_over_zenoh():
    ep = f"tcp/127.0.0.1:{free_port()}"
    with can.Bus(interface="sctd", channel="testbot", listen=ep) as a, \
            can.Bus(interface="sctd", channel="testbot", connect=ep) as b:
        msg = can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\x01\x02")

        def delivered():
            a.send(msg)
            return b.recv(0.1)
        got = wait_for(delivered, 10)
        assert got is not None and got.arbitration_id == 0x123 and bytes(got.data) == b"\x01\x02"
        assert a.recv(0.2) is None  # no echo of its own frames
        assert isinstance(a, ZenohBus) and a.dropped == 0


@pytest.mark.slow
def test_can_logger_watches_a_running_sim_and_frames_reach_its_bus(tmp_path):
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    sim = sctd("sim", "--task", "pour", "--listen", ep, log=tmp_path / "sim.log")
    logger = None
    try:
        with open_session(connect=[ep]) as s:
            scenes: list[dict] = []
            sub = s.declare_subscriber(Keys().scene, lambda smp: scenes.append(
                msgpack.unpackb(smp.payload.to_bytes(), raw=False)))
            assert wait_for(lambda: scenes, 60), sim.output()
            logger = Proc("can.logger", "-i", "sctd", "-c", "edan", "--bus-kwargs", f"connect={ep}",
                          log=tmp_path / "logger.log")

            ids_seen = re.compile(r"ID:\s+([0-9a-f]{3})\s")

            def all_ids() -> bool:
                ids = set(ids_seen.findall(logger.output()))
                return {"080", "181", "187", "201", "207"} <= ids
            assert wait_for(all_ids, 30, interval=0.5), logger.output()[-2000:]

            # a frame sent by another python-can user lands on the simulator's bus:
            # the drives do not know id 0x555 and count it
            with can.Bus(interface="sctd", channel="edan", connect=ep) as bus:
                def injected() -> bool:
                    bus.send(can.Message(arbitration_id=0x555, is_extended_id=False, data=bytes(8)))
                    return bool(scenes) and scenes[-1]["can_injected"] > 0 and \
                        scenes[-1]["link"]["drives_rx"]["unknown"] > 0
                assert wait_for(injected, 10, interval=0.2), scenes[-1]
            sub.undeclare()
        logger.p.send_signal(signal.SIGINT)  # the logger's clean exit
        logger.p.wait(20)
    finally:
        if logger is not None:
            logger.stop()
        rc = sim.stop()
    assert rc == 0, sim.output()
    assert port_is_free(port)
