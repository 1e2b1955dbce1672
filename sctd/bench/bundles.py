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
import zipfile
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

from sctd.skill import Bundle, bundle_from_file
from sctd.skill.loader import MAX_BUNDLE_BYTES


def malformed_bundles(skills: Path) -> list[tuple[str, bytes]]:
    """Twenty different bundles the daemon must refuse with an error reply, from the
    shipped skills in ``skills``: bytes that are not a bundle, bundles whose YAML or
    model files are broken, hostile or invalid."""
    pour = bundle_from_file(skills / "pour.yaml")
    vf = bundle_from_file(skills / "pour-vf.yaml")
    rel = next(iter(vf.files))
    bomb = io.BytesIO()
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("points.npy", b"\0" * (300 * 1024 * 1024))

    def yaml(text: str) -> bytes:
        return Bundle(pour.name, text, {}).pack()

    def edit(old: str, new: str) -> bytes:
        assert old in pour.yaml_text, old  # each case must really break the skill
        return yaml(pour.yaml_text.replace(old, new))

    def packed(**fields: Any) -> bytes:
        m = {"format": "sctd-skill-bundle", "version": 1, "name": "x.yaml", "yaml": pour.yaml_text,
             "files": {}}
        m.update(fields)
        return msgpack.packb(m, use_bin_type=True)

    def long_description(n: int) -> str:
        line = next(ln for ln in pour.yaml_text.splitlines() if ln.startswith("description:"))
        block = "description: |\n" + "".join(f"  line {k} of a long description\n" for k in range(n))
        return pour.yaml_text.replace(line + "\n", block)

    return [
        ("garbage bytes", b"\x00\xffnot msgpack at all"),
        ("a msgpack list", msgpack.packb([1, 2, 3])),
        ("truncated bundle", pour.pack()[:-40]),
        ("wrong format", packed(format="zip", version=99)),
        ("files not bytes", packed(files={"m.npz": "text"})),
        ("escaping file name", Bundle(vf.name, vf.yaml_text, {**vf.files, "../x.npz": b""}).pack()),
        ("corrupt npz", Bundle(vf.name, vf.yaml_text, {rel: b"PK\x03\x04broken"}).pack()),
        ("npz zip bomb", Bundle(vf.name, vf.yaml_text, {rel: bomb.getvalue()}).pack()),
        ("missing model file", Bundle(vf.name, vf.yaml_text, {}).pack()),
        ("deeply nested yaml", yaml("[" * 5000)),
        ("yaml syntax error", yaml("states: [a, b\nfsm: {")),
        ("duplicate keys", yaml(pour.yaml_text + "\nname: again\n")),
        ("unknown field", yaml(pour.yaml_text + "\nspeed_of_light: 3e8\n")),
        ("not a mapping", yaml("- just\n- a list\n")),
        ("negative angle", edit("max_angle: 0.10", "max_angle: -1")),
        ("empty object", edit("object: mug", "object: ''")),
        ("non-unit quaternion", edit("[0.0, 0.0, 0.12, 0.0, 0.0, 0.0, 1.0]",
                                     "[0.0, 0.0, 0.12, 0.0, 0.0, 0.0, 3.0]")),
        ("nan limit", edit("max_linear_speed: 0.10 ", "max_linear_speed: .nan ")),
        ("7 MB yaml (parsed)", yaml(long_description(200_000))),
        ("10 MB yaml (too big)", yaml(long_description(300_000))),
    ]


def big_bundle(skills: Path, seed: int, size: int = MAX_BUNDLE_BYTES - 4096) -> Bundle:
    """The shipped ``pour-vf`` skill with its model grown to a packed bundle of about
    ``size`` bytes (at most the limit): each demonstration point repeated with 0.5 mm of
    noise (quaternions 1e-3, normalised), stored uncompressed. ``seed`` makes bundles
    that differ (other ids) and behave alike."""
    vf = bundle_from_file(skills / "pour-vf.yaml")
    rel = next(iter(vf.files))
    with np.load(io.BytesIO(vf.files[rel]), allow_pickle=False) as z:
        fields, P, Q, R = z["fields"], z["points"], z["quaternions"], z["responsibilities"]
    room = size - len(Bundle(vf.name, vf.yaml_text, {rel: b""}).pack()) - 2048  # 2 kB: the npz's own
    n = room // (8 * (P.shape[1] + Q.shape[1] + R.shape[1]))
    rng = np.random.default_rng(seed)
    i = np.arange(n) % len(P)
    Q2 = Q[i] + rng.normal(scale=1e-3, size=(n, 4))
    buf = io.BytesIO()
    np.savez(buf, fields=fields, points=P[i] + rng.normal(scale=5e-4, size=(n, 3)),
             quaternions=Q2 / np.linalg.norm(Q2, axis=1)[:, None], responsibilities=R[i])
    return Bundle(vf.name, vf.yaml_text, {rel: buf.getvalue()})
