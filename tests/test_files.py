"""Every file sctd reads goes through one strict, bounded reader (sctd.files): regular
files only, capped before they are read, inside their folder where that matters, UTF-8,
and YAML without duplicate keys, runaway aliases or deep nesting. Errors name the file,
the place and the problem, and never quote the file."""

import os
import shutil
from pathlib import Path

import pytest

from sctd.files import FileError, load_yaml, parse_yaml, read_bytes
from sctd.skill import SkillError, load_skill
from sctd_services.input.device import InputError
from sctd_services.input.mapping import load_mapping

ROOT = Path(__file__).resolve().parents[1]
MAP = "version: 1\naxes: [{source: 0}]\nbuttons: {mode: 0, enable: 10, escape: 1}\n"


def test_a_duplicate_key_in_a_mapping_file_is_refused(tmp_path):
    """The audit's case: ``enable: 10, enable: null`` held the deadman with no key
    pressed (the last of two keys won)."""
    f = tmp_path / "dup.yaml"
    f.write_text("version: 1\naxes: [{source: 0}]\nbuttons: {enable: 10, enable: null}\n")
    with pytest.raises(InputError, match=r"dup\.yaml: line 3: invalid YAML \(duplicate key 'enable'\)"):
        load_mapping(f)
    f.write_text(MAP)
    assert load_mapping(f).buttons["enable"] == 10


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom", "/dev/null"])
def test_devices_are_refused_before_a_byte_is_read(device):
    with pytest.raises(FileError, match="a character device, not a regular file"):
        read_bytes(device, 1 << 20)
    with pytest.raises(InputError, match=f"{device}: a character device"):
        load_mapping(device)


def test_fifos_directories_and_missing_files_are_refused(tmp_path):
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)  # opened without blocking: nothing writes to it
    with pytest.raises(FileError, match="a FIFO, not a regular file"):
        load_yaml(fifo)
    with pytest.raises(FileError, match="a directory, not a regular file"):
        load_yaml(tmp_path)
    with pytest.raises(FileError, match=r"missing\.yaml: cannot open \(No such file"):
        load_yaml(tmp_path / "missing.yaml")


def test_a_file_over_its_cap_is_refused_naming_the_cap(tmp_path):
    f = tmp_path / "big.yaml"
    f.write_text("x: [" + "1, " * 400_000 + "1]\n")
    with pytest.raises(FileError, match=r"big\.yaml: \d+ bytes, more than the 1048576 allowed"):
        load_yaml(f)
    assert len(read_bytes(f, 2 << 20)) == f.stat().st_size


def test_aliases_that_expand_past_the_bound_are_refused():
    laughs = ["a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    for k, name in enumerate("bcdefghij"):
        prev = "abcdefghij"[k]
        laughs.append(f"{name}: &{name} [" + ", ".join([f"*{prev}"] * 9) + "]")
    text = "\n".join(laughs) + "\n"
    assert len(text) < 1000
    with pytest.raises(FileError, match=r"laughs: line \d+: aliases expand to more than 100000 nodes"):
        parse_yaml(text, "laughs")
    # a few shared aliases are fine
    assert parse_yaml("a: &a [1, 2]\nb: *a\nc: *a\n", "ok") == {"a": [1, 2], "b": [1, 2], "c": [1, 2]}


def test_recursive_aliases_deep_nesting_and_bad_bytes_are_errors_not_tracebacks():
    with pytest.raises(FileError, match="an alias refers to the node that contains it"):
        parse_yaml("&a [*a]", "rec")
    with pytest.raises(FileError, match="nested deeper than 64 levels"):
        parse_yaml("[" * 100 + "]" * 100, "deep")
    with pytest.raises(FileError, match=r"deeper: line 1: invalid YAML"):
        parse_yaml("[" * 100_000 + "]" * 100_000, "deeper")
    with pytest.raises(FileError, match=r"bytes: not UTF-8 text \(byte 3\)"):
        from sctd.files import decode_text
        decode_text(b"ok:\xff\xfe", "bytes")


def _skill_folder(tmp_path: Path) -> Path:
    d = tmp_path / "skill"
    d.mkdir()
    for f in (ROOT / "skills").glob("pour-vf*"):  # the skill and its states' model files
        shutil.copy(f, d / f.name)
    return d


def test_a_model_file_must_resolve_inside_the_skill_folder(tmp_path):
    d = _skill_folder(tmp_path)
    assert load_skill(d / "pour-vf.yaml").name
    secret = tmp_path / "secret.npz"
    secret.write_bytes(b"PASSWORD=hunter2\n" * 40)
    (d / "pour-vf-s1.npz").unlink()
    (d / "pour-vf-s1.npz").symlink_to(secret)
    with pytest.raises(SkillError) as e:
        load_skill(d / "pour-vf.yaml")
    assert "resolves outside" in str(e.value) and "hunter2" not in str(e.value)
    (d / "pour-vf-s1.npz").unlink()
    (d / "pour-vf-s1.npz").symlink_to("/dev/zero")
    with pytest.raises(SkillError, match="resolves outside"):
        load_skill(d / "pour-vf.yaml")


def test_a_skill_file_that_is_a_device_or_too_big_is_refused(tmp_path):
    with pytest.raises(SkillError, match="/dev/zero: a character device"):
        load_skill("/dev/zero")
    d = _skill_folder(tmp_path)
    f = d / "pour-vf.yaml"
    f.write_text(f.read_text() + "#" * (8 * 1024 * 1024) + "\n")
    with pytest.raises(SkillError, match="more than the 8388608 allowed"):
        load_skill(f)
