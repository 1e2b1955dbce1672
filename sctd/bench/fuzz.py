"""``sctd bench fuzz``: coverage-guided fuzzing (atheris, libFuzzer) of everything that
decodes bytes from outside: the wire decoders, the CAN frame mirror, the skill bundle
unpacker, the skill YAML loader, the vector-field model files, and the file loaders (the
strict YAML reader every file goes through, input mapping files, ``sctd log`` files as
``sctd replay`` reads them).

Each target has its documented errors (``DecodeError``, ``FrameDecodeError``,
``SkillError``, ``FileError`` and ``InputError``, ``LogError``): any other exception
escaping a decoder is a crash, which atheris reports with the input that caused it, and
the target fails. Each target runs in its own process (``python -m sctd.bench.fuzz
TARGET -runs=N``: libFuzzer exits the process when it is done), seeded with valid
messages and the shipped skills, and instruments only sctd's own modules. Those are
imported inside the functions that build the seeds and harnesses, not at the top of this
module: atheris instruments a module only when it is first imported within
``atheris.instrument_imports()``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from importlib import resources
from pathlib import Path

TARGETS = ("input", "state", "object", "target", "demo", "can", "bundle", "skill_yaml", "model_npz",
           "model_json", "yaml", "map", "mcap")
# The folder holding this sctd package (the checkout, or site-packages): the fuzzing child
# runs there, so that ``python -m sctd.bench.fuzz`` imports this same sctd.
IMPORT_ROOT = Path(__file__).resolve().parents[2]


def _default_task() -> tuple[str, str]:
    """The name and object of the task the seeds' demonstrations and objects are of (the
    default task, ``sctd/app/defaults.yaml``)."""
    from ..app.defaults import defaults
    from ..task import find_task

    task = find_task(defaults().task)
    return task.name, task.object


def _seeds(target: str, skills: Path) -> list[bytes]:
    """Valid inputs a target starts from (libFuzzer mutates them)."""
    import msgpack

    from ..wire import codec

    pose = [0.4, 0.1, 0.9, 0.0, 0.0, 0.0, 1.0]
    if target == "input":
        return [codec.encode_input(1, 1.0, [0.1, -0.2, 0.3]), codec.encode_input(2, 2.0, [0.0] * 6)]
    if target == "state":
        return [codec.encode_state(1, 1.0, pose), codec.encode_state(2, 2.0, pose, q=[0.1] * 7,
                                                                     dq=[0.0] * 7, wrench=[0.0] * 6)]
    if target == "object":
        return [codec.encode_object(1, 1.0, pose)]
    if target == "target":
        return [codec.encode_target(1, 1.0, pose, "carry", "abc", 3)]
    if target == "demo":
        task, obj = _default_task()
        return [codec.encode_demo(task, "demo_000", obj,
                                  [[0.01 * k, 0.3, 0.0, 0.03, 0.0, 0.0, 0.0, 1.0] for k in range(12)])]
    if target == "can":
        return [msgpack.packb({"v": 1, "frames": [[1.0, 0x80, False, 0, b""],
                                                  [1.0, 0x101, False, 8, b"\x01" * 8]]})]
    if target in ("yaml", "map"):
        maps = Path(str(resources.files("sctd_services") / "input" / "maps"))  # package data
        return [p.read_bytes() for p in sorted(maps.glob("*.yaml"))] + (
            [p.read_bytes() for p in sorted(skills.glob("*.yaml"))] if target == "yaml" else [])
    if target == "mcap":
        return [_log_seed()]
    from ..skill import bundle_from_file

    bundles = [bundle_from_file(p) for p in sorted(skills.glob("*.yaml"))]
    if target == "bundle":
        return [b.pack() for b in bundles]
    if target == "skill_yaml":
        return [b.yaml_text.encode() for b in bundles if not b.files]
    if target == "model_npz":
        return [data for b in bundles for rel, data in b.files.items() if rel.endswith(".npz")]
    if target == "model_json":
        from ..skill import vector_field_model_from_bytes, vector_field_model_to_bytes

        return [vector_field_model_to_bytes(vector_field_model_from_bytes(data, rel, rel), "m.json")
                for b in bundles for rel, data in b.files.items() if rel.endswith(".npz")]
    raise ValueError(f"unknown fuzz target {target!r} (known: {', '.join(TARGETS)})")


def _log_seed() -> bytes:
    """A small ``sctd log`` file: states, a target, an object and an input."""
    from ..cli.log import McapLog
    from ..wire import Keys, codec

    keys = Keys()
    pose = [0.4, 0.1, 0.9, 0.0, 0.0, 0.0, 1.0]
    with tempfile.TemporaryDirectory() as d:
        log = McapLog(Path(d) / "seed.mcap")
        for k in range(5):
            log.add(keys.state, "state", codec.encode_state(k, 1.0 + k, pose), 1.0 + k)
        log.add(keys.target, "target", codec.encode_target(1, 2.0, pose, "carry", "abc", 3), 2.0)
        log.add(keys.objects(_default_task()[1]), "objects", codec.encode_object(1, 2.0, pose), 2.0)
        log.add(keys.input("pad"), "input", codec.encode_input(1, 2.0, [0.1, 0.0, 0.0], [0, 1, 0]), 2.0)
        log.close()
        return (Path(d) / "seed.mcap").read_bytes()


def _file_harness(target: str) -> Callable[[bytes], None]:
    """The file loaders' targets: ``yaml`` (sctd.files), ``map``, ``mcap``."""
    from ..files import FileError, decode_text, parse_yaml

    if target == "mcap":
        import io

        from ..cli.log import LogError, read_messages

        def one_mcap(data: bytes) -> None:
            try:
                for _ in read_messages(io.BytesIO(data), "fuzz.mcap"):
                    pass
            except LogError:
                pass
        return one_mcap
    from sctd_services.input.device import InputError
    from sctd_services.input.mapping import parse_mapping

    def one_file(data: bytes) -> None:
        try:
            doc = parse_yaml(decode_text(data, "fuzz.yaml"), "fuzz.yaml")
            if target == "map":
                parse_mapping(doc, "fuzz.yaml")
        except (FileError, InputError):
            pass
    return one_file


def _harness(target: str) -> Callable[[bytes], None]:
    """``test_one_input(data)`` for a target: its documented error is caught, anything
    else escapes (a crash)."""
    if target in ("yaml", "map", "mcap"):
        return _file_harness(target)
    if target in ("input", "state", "object", "target", "demo"):
        from ..wire import codec

        decode = {"input": codec.decode_input, "state": codec.decode_state,
                  "object": codec.decode_object, "target": codec.decode_target,
                  "demo": codec.decode_demo}[target]

        def one(data: bytes) -> None:
            try:
                decode(data)
            except codec.DecodeError:
                pass
        return one
    if target == "can":
        from sctd_sim.canbus.zenoh_interface import FrameDecodeError, decode_frames

        def one_can(data: bytes) -> None:
            try:
                decode_frames(data)
            except FrameDecodeError:
                pass
        return one_can

    from ..skill import Bundle, SkillError, skill_from_bundle, vector_field_model_from_bytes

    if target == "bundle":
        def one_bundle(data: bytes) -> None:
            try:
                skill_from_bundle(Bundle.unpack(data))
            except SkillError:
                pass
        return one_bundle
    if target == "skill_yaml":
        def one_yaml(data: bytes) -> None:
            try:
                skill_from_bundle(Bundle("fuzz.yaml", data.decode("utf-8", "replace"), {}))
            except SkillError:
                pass
        return one_yaml
    rel = "m.npz" if target == "model_npz" else "m.json"

    def one_model(data: bytes) -> None:
        try:
            vector_field_model_from_bytes(data, rel, rel)
        except SkillError:
            pass
    return one_model


def _instrumented(target: str) -> Callable[[bytes], None]:
    import atheris

    with atheris.instrument_imports(include=["sctd", "sctd_sim", "sctd_services"]):
        return _harness(target)


def child_main(argv: list[str]) -> int:
    """``python -m sctd.bench.fuzz TARGET [libFuzzer flags] [corpus dirs]``."""
    import atheris

    target = argv[0]
    one = _instrumented(target)
    atheris.Setup([sys.argv[0], *argv[1:]], one)
    atheris.Fuzz()  # exits the process
    return 0


def run_target(target: str, runs: int, skills: Path, workdir: Path, max_len: int = 65536,
               timeout: float | None = None) -> dict:
    """Fuzz one target for ``runs`` inputs in a child process; its outcome and figures."""
    corpus = workdir / target
    corpus.mkdir(parents=True, exist_ok=True)
    for i, seed in enumerate(_seeds(target, skills)):
        (corpus / f"seed{i}").write_bytes(seed)
    artifacts = workdir / f"{target}-crashes"
    artifacts.mkdir(exist_ok=True)
    cmd = [sys.executable, "-m", "sctd.bench.fuzz", target, f"-runs={runs}", f"-max_len={max_len}",
           "-rss_limit_mb=4096", "-timeout=20", f"-artifact_prefix={artifacts}/", "-print_final_stats=1",
           str(corpus)]
    t0 = time.monotonic()
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=IMPORT_ROOT,
                       env={**os.environ, "PYTHONHASHSEED": "0"})
    seconds = time.monotonic() - t0
    log = p.stdout + p.stderr
    stats = {}
    for line in log.splitlines():
        if line.startswith("stat::"):
            name, _, value = line[len("stat::"):].partition(":")
            stats[name.strip()] = value.strip()
    crashes = sorted(str(c) for c in artifacts.iterdir())
    return {"target": target, "ok": p.returncode == 0 and not crashes, "returncode": p.returncode,
            "runs": int(stats.get("number_of_executed_units", 0)), "seconds": round(seconds, 1),
            "coverage": _coverage(log), "crashes": crashes,
            "log_tail": "" if p.returncode == 0 else "\n".join(log.splitlines()[-40:])}


def _coverage(log: str) -> int | None:
    """The last ``cov:`` figure libFuzzer printed (edges covered)."""
    cov = None
    for line in log.splitlines():
        if " cov: " in line:
            try:
                cov = int(line.split(" cov: ", 1)[1].split()[0])
            except (IndexError, ValueError):
                pass
    return cov


def add_fuzz_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--runs", type=int, default=1_000_000, help="inputs per target (default %(default)s)")
    p.add_argument("--target", action="append", choices=TARGETS,
                   help="fuzz only this target (repeatable; default all)")
    p.add_argument("--skills", help="folder of the seed skills (default: the shipped skills)")
    p.add_argument("--keep", metavar="DIR", help="keep corpora and crash inputs here")
    p.add_argument("--json", action="store_true")


def main_fuzz(args: argparse.Namespace) -> int:
    try:
        import atheris  # noqa: F401
    except ImportError:
        print("sctd bench fuzz: needs atheris (pip install 'sctd[dev]'; make setup installs it)",
              file=sys.stderr)
        return 2
    # not at the top: the child imports this module, and sctd's modules only afterwards,
    # under atheris' instrumentation
    from sctd.skill.catalog import shipped_folder

    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="sctd-fuzz-"))
    skills = Path(args.skills) if args.skills else shipped_folder()
    results = [run_target(t, args.runs, skills, work) for t in (args.target or TARGETS)]
    if not args.keep and all(r["ok"] for r in results):
        shutil.rmtree(work)  # corpora of a clean run; a crash's inputs are kept and named
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        print(f"sctd bench fuzz: {args.runs} inputs per target (atheris/libFuzzer); only the documented "
              "errors may escape")
        for r in results:
            mark = "ok" if r["ok"] else "CRASH"
            crashes = f"; crash inputs: {r['crashes']}" if r["crashes"] else ""
            print(f"  {r['target']:11s} {mark:5s} {r['runs']:>9d} inputs in {r['seconds']:7.1f} s, "
                  f"coverage {r['coverage']} edges{crashes}")
            if not r["ok"]:
                print(r["log_tail"])
    return 0 if all(r["ok"] for r in results) else 1


if __name__ == "__main__":
    sys.exit(child_main(sys.argv[1:]))
