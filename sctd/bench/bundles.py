"""The bundles ``sctd bench robustness`` sends the daemon's skill server: malformed ones
it must refuse with an error reply, and big ones near the size limit it must swap in
without a late tick.

The tests that assert those refusals and swaps (``tests/test_e2e_safety.py``,
``tests/test_skillserver.py``, ``tests/test_frames.py``) send the same bundles. They are
here, in the package, rather than with the tests because the installed bench sends them
too, and it cannot import from ``tests/``.
"""

from __future__ import annotations

import io
import re
import zipfile
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

from sctd.skill import Bundle, bundle_from_file
from sctd.skill.loader import MAX_BUNDLE_BYTES


def malformed_bundles(skill: Path, learned: Path) -> list[tuple[str, bytes]]:
    """Twenty different bundles the daemon must refuse with an error reply, from two skill
    files: ``skill`` (with a tilt cone's ``max_angle``, a frame's pose and
    ``max_linear_speed`` in its YAML) and ``learned`` (with a model file): bytes that are
    not a bundle, bundles whose YAML or model files are broken, hostile or invalid."""
    hand = bundle_from_file(skill)
    vf = bundle_from_file(learned)
    rel = next(iter(vf.files))
    bomb = io.BytesIO()
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("points.npy", b"\0" * (300 * 1024 * 1024))

    def yaml(text: str) -> bytes:
        return Bundle(hand.name, text, {}).pack()

    def edit(pattern: str, new: str) -> bytes:
        text, n = re.subn(pattern, new, hand.yaml_text, count=1, flags=re.MULTILINE)
        assert n == 1 and text != hand.yaml_text, pattern  # each case must really break the skill
        return yaml(text)

    def packed(**fields: Any) -> bytes:
        m = {"format": "sctd-skill-bundle", "version": 1, "name": "x.yaml", "yaml": hand.yaml_text,
             "files": {}}
        m.update(fields)
        return msgpack.packb(m, use_bin_type=True)

    def long_description(n: int) -> str:
        line = next(ln for ln in hand.yaml_text.splitlines() if ln.startswith("description:"))
        block = "description: |\n" + "".join(f"  line {k} of a long description\n" for k in range(n))
        return hand.yaml_text.replace(line + "\n", block)

    return [
        ("garbage bytes", b"\x00\xffnot msgpack at all"),
        ("a msgpack list", msgpack.packb([1, 2, 3])),
        ("truncated bundle", hand.pack()[:-40]),
        ("wrong format", packed(format="zip", version=99)),
        ("files not bytes", packed(files={"m.npz": "text"})),
        ("escaping file name", Bundle(vf.name, vf.yaml_text, {**vf.files, "../x.npz": b""}).pack()),
        ("corrupt npz", Bundle(vf.name, vf.yaml_text, {**vf.files, rel: b"PK\x03\x04broken"}).pack()),
        ("npz zip bomb", Bundle(vf.name, vf.yaml_text, {**vf.files, rel: bomb.getvalue()}).pack()),
        ("missing model file", Bundle(vf.name, vf.yaml_text, {}).pack()),
        ("deeply nested yaml", yaml("[" * 5000)),
        ("yaml syntax error", yaml("states: [a, b\nfsm: {")),
        ("duplicate keys", yaml(hand.yaml_text + "\nname: again\n")),
        ("unknown field", yaml(hand.yaml_text + "\nspeed_of_light: 3e8\n")),
        ("not a mapping", yaml("- just\n- a list\n")),
        ("negative angle", edit(r"max_angle: [0-9.]+", "max_angle: -1")),
        ("empty object", edit(r"^object: .*$", "object: ''")),
        # a frame's pose [x, y, z, qx, qy, qz, qw] with its quaternion 3 long
        ("non-unit quaternion", edit(r"(pose: \[(?:[^,\]]+, ){6})([^,\]]+)\]", r"\g<1>3.0]")),
        ("nan limit", edit(r"max_linear_speed: [0-9.]+", "max_linear_speed: .nan")),
        ("7 MB yaml (parsed)", yaml(long_description(200_000))),
        ("10 MB yaml (too big)", yaml(long_description(300_000))),
    ]


def big_bundle(learned: Path, seed: int, size: int = MAX_BUNDLE_BYTES - 4096) -> Bundle:
    """The vector-field skill file ``learned`` with its models grown to a packed bundle of
    about ``size`` bytes (at most the limit), the room shared equally among its model
    files (one per state of a skill learned as states): each demonstration point
    repeated with 0.5 mm of noise (quaternions 1e-3, normalised), stored uncompressed.
    ``seed`` makes bundles that differ (other ids) and behave alike."""
    vf = bundle_from_file(learned)
    room = size - len(Bundle(vf.name, vf.yaml_text, {rel: b"" for rel in vf.files}).pack())
    room = room // len(vf.files) - 2048  # 2 kB: each npz's own
    rng = np.random.default_rng(seed)
    files = {}
    for rel, data in vf.files.items():
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            fields, P, Q, R = z["fields"], z["points"], z["quaternions"], z["responsibilities"]
        n = room // (8 * (P.shape[1] + Q.shape[1] + R.shape[1]))
        i = np.arange(n) % len(P)
        Q2 = Q[i] + rng.normal(scale=1e-3, size=(n, 4))
        buf = io.BytesIO()
        np.savez(buf, fields=fields, points=P[i] + rng.normal(scale=5e-4, size=(n, 3)),
                 quaternions=Q2 / np.linalg.norm(Q2, axis=1)[:, None], responsibilities=R[i])
        files[rel] = buf.getvalue()
    return Bundle(vf.name, vf.yaml_text, files)
