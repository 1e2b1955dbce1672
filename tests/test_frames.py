"""Objects over a socket pair with their large buffers out of band
(sctd.runtime.frames): a skill arrives equal, its model arrays as views of memory maps
(not copied into bytes); an end that closes mid-message or a header that is not ours is
an error, not a hang."""

from __future__ import annotations

import mmap
import struct
import threading

import numpy as np
import pytest

from sctd.runtime import frames
from sctd.skill import Bundle, skill_from_bundle, skill_summary
from tests.conftest import ROOT

POUR_VF = ROOT / "skills" / "pour-vf.yaml"


def _through_link(obj):
    a, b = frames.pair()
    with a, b:
        writer = threading.Thread(target=frames.send, args=(a, obj))
        writer.start()
        got = frames.receive(b)
        writer.join()
        return got


def _mapped(a: np.ndarray) -> bool:
    base = a
    while isinstance(base, np.ndarray) and base.base is not None:
        base = base.base
    return isinstance(base, mmap.mmap) or (isinstance(base, memoryview) and isinstance(base.obj, mmap.mmap))


def test_a_large_skill_arrives_equal_with_its_model_arrays_on_memory_maps():
    from sctd.bench.bundles import big_bundle

    skill = skill_from_bundle(Bundle.unpack(big_bundle(POUR_VF, seed=3, size=2 << 20).pack()))
    got = _through_link(("swap", 7, skill))
    assert got[:2] == ("swap", 7)
    back = got[2]
    assert skill_summary(back) == skill_summary(skill) and back.id == skill.id
    model, model_back = (s.states[0].input_mappings[0].model for s in (skill, back))
    for name in ("points", "quaternions", "responsibilities"):
        a, b = getattr(model, name), getattr(model_back, name)
        assert np.array_equal(a, b) and b.flags.c_contiguous
        assert _mapped(b), name
    # shared objects stay shared: the constraint reads the same model as the mapping
    assert back.states[0].active_constraints[0].model is model_back


def test_small_objects_and_buffers_travel_in_the_pickle():
    obj = {"a": np.arange(10.0), "b": b"x" * 100, "c": [1, "two"]}
    got = _through_link(obj)
    assert np.array_equal(got["a"], obj["a"]) and got["b"] == obj["b"] and got["c"] == obj["c"]
    assert not _mapped(got["a"])


def test_an_end_closed_mid_message_is_an_eof_error():
    a, b = frames.pair()
    with b:
        with a:
            a.sendall(frames.HEADER.pack(100, 1) + struct.pack("!Q", 1 << 20) + b"\x80" * 10)
        with pytest.raises(EOFError):
            frames.receive(b)


@pytest.mark.parametrize("head", [frames.HEADER.pack(10, frames.MAX_BUFFERS + 1),
                                  frames.HEADER.pack(frames.MAX_MESSAGE + 1, 0)])
def test_a_header_that_is_not_ours_is_refused(head):
    a, b = frames.pair()
    with a, b:
        a.sendall(head)
        with pytest.raises(ValueError):
            frames.receive(b)
