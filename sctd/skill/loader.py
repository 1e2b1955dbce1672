"""Skill files: YAML + model files -> validated :class:`~sctd.skill.model.Skill`.

Every skill travels as a :class:`Bundle` (the YAML text plus the model files it names,
by relative path); loading from disk first builds the bundle, so a skill from a file
and a skill from the hot-swap query go through the same validation. Errors read
``file: path.to.field: what is wrong``. Model files are JSON or pickle-free ``.npz``
(:mod:`sctd.skill.modelfile`). Each element of a state or of the FSM is read by the
class its ``type`` names, found in the registry of its kind.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack

from ..files import FileError, inside, parse_yaml, read_bytes, read_text
from .constraints import CONSTRAINTS
from .errors import SkillError
from .frames import BUILTIN_FRAMES, Frame, builtin_frames
from .gripper import GripperAction
from .mappings import MAPPINGS
from .model import Limits, Skill, State
from .reader import Reader, check_relative, kind_of
from .region import Region
from .registry import Registry
from .transitions import TRANSITIONS, Transition

FORMAT_VERSION = 1
BUNDLE_FORMAT = "sctd-skill-bundle"
# A packed bundle's largest size: what one hot-swap query may carry. The runtime's skill
# server copies it, validates it and hands the skill on, each in memory and time that
# grow with it; a vector-field model of 20k demonstration points is 1.4 MB compressed.
MAX_BUNDLE_BYTES = 8 * 1024 * 1024
MAX_TEXT = 10_000  # characters of a skill's name or description
MAX_NAME = 64  # characters of a state's object: a body's name (the wire's names)
_NOT_IN_NAMES = frozenset("/\\*$?#@ ")


@dataclass(frozen=True)
class Bundle:
    """A self-contained skill: YAML text and the model files it references."""

    name: str  # the YAML file's name, for messages
    yaml_text: str
    files: Mapping[str, bytes]

    @property
    def id(self) -> str:
        """Content hash: equal bundles have equal ids wherever they were loaded from."""
        h = hashlib.sha256()
        h.update(self.yaml_text.encode())
        for rel in sorted(self.files):
            h.update(b"\0" + rel.encode() + b"\0")
            h.update(hashlib.sha256(self.files[rel]).digest())
        return h.hexdigest()[:16]

    def pack(self) -> bytes:
        """msgpack bytes for the ``sctd/<robot>/skill`` query payload."""
        return msgpack.packb(
            {
                "format": BUNDLE_FORMAT,
                "version": FORMAT_VERSION,
                "name": self.name,
                "yaml": self.yaml_text,
                "files": dict(self.files),
            },
            use_bin_type=True,
        )

    @classmethod
    def unpack(cls, data: bytes) -> Bundle:
        """Decode a packed bundle; raise SkillError naming what is malformed."""
        where = "<bundle>"
        if len(data) > MAX_BUNDLE_BYTES:
            raise SkillError(where, "", f"bundle of {len(data)} bytes exceeds {MAX_BUNDLE_BYTES}")
        try:
            obj = msgpack.unpackb(data, raw=False, strict_map_key=True)
        except Exception as exc:  # msgpack raises several unrelated types
            raise SkillError(where, "", f"not a msgpack skill bundle ({exc})") from None
        if not isinstance(obj, dict) or obj.get("format") != BUNDLE_FORMAT:
            raise SkillError(where, "format", f"expected {BUNDLE_FORMAT!r}")
        if obj.get("version") != FORMAT_VERSION:
            raise SkillError(where, "version", f"unsupported version {obj.get('version')!r}")
        name, text, files = obj.get("name"), obj.get("yaml"), obj.get("files", {})
        if not isinstance(name, str) or not isinstance(text, str):
            raise SkillError(where, "name/yaml", "expected strings")
        if not isinstance(files, dict) or not all(
            isinstance(k, str) and isinstance(v, bytes) for k, v in files.items()
        ):
            raise SkillError(name, "files", "expected a map of relative path -> bytes")
        for rel in files:
            check_relative(name, f"files[{rel!r}]", rel)
        return cls(name=name, yaml_text=text, files=files)


def bundle_from_file(path: str | Path) -> Bundle:
    """Read a skill YAML and every model file it references (relative to the YAML):
    regular files only, resolved (symlinks included) inside the YAML's folder, at most
    :data:`MAX_BUNDLE_BYTES` together, read no further than that (:mod:`sctd.files`)."""
    path = Path(path)
    try:
        text = read_text(path, MAX_BUNDLE_BYTES)
        doc = _parse_yaml(str(path), text)
        files: dict[str, bytes] = {}
        left = MAX_BUNDLE_BYTES - len(text.encode())
        for where, rel in _model_references(doc):
            check_relative(str(path), where, rel)
            # the model file, after symlinks, must be inside the skill's folder
            target = inside(path.parent / rel, path.parent, str(path), where)
            if rel not in files:
                files[rel] = read_bytes(target, max(left, 0), str(path), f"{where}: model file {rel!r}")
                left -= len(files[rel])
    except FileError as e:
        raise SkillError(e.file, e.where, e.problem) from None
    return Bundle(name=str(path), yaml_text=text, files=files)


def load_skill(path: str | Path) -> Skill:
    """Load and validate a skill file (and its model files)."""
    return skill_from_bundle(bundle_from_file(path))


def skill_from_bundle(bundle: Bundle) -> Skill:
    """Validate a bundle into a Skill; nothing is read from disk."""
    doc = _parse_yaml(bundle.name, bundle.yaml_text)
    return _Parser(bundle).skill(doc)


# --- parsing --------------------------------------------------------------------------


def _parse_yaml(file: str, text: str) -> Any:
    try:
        return parse_yaml(text, file)
    except FileError as e:
        raise SkillError(e.file, e.where, e.problem) from None


def _model_references(doc: Any) -> list[tuple[str, str]]:
    """(field path, relative file) for every ``model:`` under states."""
    refs: list[tuple[str, str]] = []
    states = doc.get("states") if isinstance(doc, dict) else None
    if not isinstance(states, dict):
        return refs
    for sname, state in states.items():
        if not isinstance(state, dict):
            continue
        for key in ("input_mapping", "active_constraints"):
            items = state.get(key) or []
            if not isinstance(items, list):
                continue
            for i, item in enumerate(items):
                if isinstance(item, dict) and isinstance(item.get("model"), str):
                    refs.append((f"states.{sname}.{key}[{i}].model", item["model"]))
    return refs


class _Parser(Reader):
    """Walks the YAML document, checking each field and naming its path on error."""

    def __init__(self, bundle: Bundle):
        super().__init__(bundle.name, bundle.files)
        self.bundle = bundle

    def skill(self, doc: Any) -> Skill:
        doc = self.mapping(doc, "")
        self.known_keys(doc, "", {"sctd_skill", "name", "description", "object", "limits",
                                  "frames", "fsm", "states", "candidate_frames", "region"})
        version = doc.get("sctd_skill")
        if version != FORMAT_VERSION:
            raise self.fail("sctd_skill", f"expected format version {FORMAT_VERSION}, got {version!r}")
        name, obj, description = self.texts(doc)
        limits = self.limits(doc)
        self.frames = self.frame_table(doc.get("frames") or {})
        states_doc = self.mapping(doc.get("states"), "states")
        if not states_doc:
            raise self.fail("states", "a skill needs at least one state")
        states = tuple(self.state(str(n), s) for n, s in states_doc.items())
        start, end, min_dwell, transitions = self.fsm(doc.get("fsm"), [s.name for s in states])
        return Skill(
            name=name, object=obj, frames=self.frames, states=states, transitions=transitions,
            start=start, end=end, limits=limits, min_dwell=min_dwell, description=description,
            id=self.bundle.id, source=self.file, candidate_frames=self.candidate_frames(doc),
            region=self.region(doc.get("region"), {obj, *(s.object for s in states if s.object)}),
        )

    def texts(self, doc: dict) -> tuple[str, str, str]:
        """The skill's name, object and description."""
        name = self.string(doc.get("name"), "name")
        obj = self.string(doc.get("object"), "object")
        description = doc.get("description", "")
        if not isinstance(description, str):
            raise self.fail("description", "expected a string")
        for key, text in (("name", name), ("description", description)):
            if len(text) > MAX_TEXT:
                raise self.fail(key, f"{len(text)} characters, at most {MAX_TEXT}")
        return name, obj, description

    def limits(self, doc: dict) -> Limits:
        limits = Limits()
        if "limits" not in doc:
            return limits
        ld = self.mapping(doc["limits"], "limits")
        self.known_keys(ld, "limits", {"max_linear_speed", "max_angular_speed"})
        return Limits(
            max_linear_speed=self.number(ld.get("max_linear_speed", limits.max_linear_speed),
                                         "limits.max_linear_speed", 0.0, 1.0, lo_open=True),
            max_angular_speed=self.number(ld.get("max_angular_speed", limits.max_angular_speed),
                                          "limits.max_angular_speed", 0.0, 3.0, lo_open=True),
        )

    def frame_table(self, frames_doc: Any) -> dict[str, Frame]:
        """The built-in frames and those the skill defines."""
        frames = builtin_frames()
        for fname, fd in (self.mapping(frames_doc, "frames")).items():
            path = f"frames.{fname}"
            if fname in BUILTIN_FRAMES:
                raise self.fail(path, f"{fname!r} is built in and cannot be redefined")
            fd = self.mapping(fd, path)
            self.known_keys(fd, path, {"parent", "pose"})
            parent = self.choice(fd.get("parent"), f"{path}.parent", BUILTIN_FRAMES)
            frames[str(fname)] = Frame(str(fname), parent, self.pose(fd.get("pose"), f"{path}.pose"))  # type: ignore[arg-type]
        return frames

    def fsm(self, fsm: Any, names: list[str]) -> tuple[str, str, float, tuple[Transition, ...]]:
        """Start and end state, minimum dwell and transitions."""
        fsm = self.mapping(fsm, "fsm")
        self.known_keys(fsm, "fsm", {"start", "end", "transitions", "min_dwell"})
        start = self.choice(fsm.get("start"), "fsm.start", tuple(names))
        end = self.choice(fsm.get("end"), "fsm.end", tuple(names))
        min_dwell = self.number(fsm.get("min_dwell", 0.05), "fsm.min_dwell", 0.0, 60.0)
        tdoc = fsm.get("transitions") or []
        if not isinstance(tdoc, list):
            raise self.fail("fsm.transitions", f"expected a list, got {kind_of(tdoc)}")
        transitions = tuple(self.transition(t, f"fsm.transitions[{i}]", tuple(names))
                            for i, t in enumerate(tdoc))
        self.check_reachable(start, end, names, transitions)
        return start, end, min_dwell, transitions

    def candidate_frames(self, doc: dict) -> tuple[dict, ...]:
        cands = doc.get("candidate_frames") or []
        if not isinstance(cands, list):
            raise self.fail("candidate_frames", "expected a list")
        for i, c in enumerate(cands):
            c = self.mapping(c, f"candidate_frames[{i}]")
            self.string(c.get("name"), f"candidate_frames[{i}].name")
            self.vector(c.get("position"), f"candidate_frames[{i}].position", 3)
        return tuple(cands)

    def region(self, v: Any, bodies: set[str]) -> Region | None:
        """``region``: a box in the frame of one of ``bodies`` (the skill's object and its
        states' own; :mod:`.region`), or None."""
        if v is None:
            return None
        d = self.mapping(v, "region")
        self.known_keys(d, "region", {"frame", "centre", "half_extents", "demonstrations"})
        frame = self.string(d.get("frame"), "region.frame")
        if frame not in bodies:
            known = ", ".join(sorted(bodies))
            raise self.fail("region.frame", f"{frame!r} is no body of the skill ({known})")
        centre = self.vector(d.get("centre"), "region.centre", 3)
        half = self.vector(d.get("half_extents"), "region.half_extents", 3)
        for i, h in enumerate(half.tolist()):
            if not 0.0 < h <= 10.0:
                raise self.fail(f"region.half_extents[{i}]", f"must be > 0 and <= 10 m, got {h}")
        n = self.integer(d.get("demonstrations", 0), "region.demonstrations")
        return Region(frame, tuple(centre.tolist()), tuple(half.tolist()), n)

    def check_reachable(self, start: str, end: str, names: list[str],
                        transitions: tuple[Transition, ...]) -> None:
        seen, todo = {start}, [start]
        while todo:
            s = todo.pop()
            for t in transitions:
                if t.source == s and t.target not in seen:
                    seen.add(t.target)
                    todo.append(t.target)
        if end not in seen:
            raise self.fail("fsm", f"end state {end!r} is not reachable from start {start!r}")
        unreachable = [n for n in names if n not in seen]
        if unreachable:
            raise self.fail(f"states.{unreachable[0]}", "state is not reachable from the start state")

    def state(self, name: str, sd: Any) -> State:
        path = f"states.{name}"
        sd = self.mapping(sd if sd is not None else {}, path)
        self.known_keys(sd, path, {"input_mapping", "active_constraints", "gripper", "object"})
        ims = sd.get("input_mapping") or []
        acs = sd.get("active_constraints") or []
        if not isinstance(ims, list):
            raise self.fail(f"{path}.input_mapping", f"expected a list, got {kind_of(ims)}")
        if not isinstance(acs, list):
            raise self.fail(f"{path}.active_constraints", f"expected a list, got {kind_of(acs)}")
        return State(
            name=name,
            input_mappings=tuple(self.element(MAPPINGS, m, f"{path}.input_mapping[{i}]")
                                 for i, m in enumerate(ims)),
            active_constraints=tuple(self.element(CONSTRAINTS, c, f"{path}.active_constraints[{i}]")
                                     for i, c in enumerate(acs)),
            gripper=None if sd.get("gripper") is None
            else GripperAction.from_yaml(self, sd["gripper"], f"{path}.gripper"),
            object=None if "object" not in sd else self.object_name(sd["object"], f"{path}.object"),
        )

    def object_name(self, v: Any, path: str) -> str:
        """A body's name as the wire's object key takes it (``objects/<name>``; the rule
        of ``sctd.wire.codec.name_problem``, a layer above, which tests hold equal): 1 to
        64 printable characters, none of ``/ \\ * $ ? # @`` or spaces, no leading dot."""
        name = self.string(v, path)
        bad = next((c for c in name if c in _NOT_IN_NAMES or not c.isprintable()), None)
        if len(name) > MAX_NAME:
            raise self.fail(path, f"expected a body's name: {len(name)} characters, at most {MAX_NAME}")
        if name.startswith("."):
            raise self.fail(path, f"expected a body's name: {name!r} starts with a dot")
        if bad is not None:
            raise self.fail(path, f"expected a body's name: {name!r} has {bad!r} (not in names: "
                                  "/ \\ * $ ? # @, spaces, control characters)")
        return name

    def element(self, registry: Registry, d: Any, path: str) -> Any:
        """An input mapping or active constraint, read by the class its ``type`` names."""
        d = self.mapping(d, path)
        kind = self.choice(d.get("type"), f"{path}.type", registry.names())
        return registry[kind].from_yaml(self, d, path)

    def transition(self, td: Any, path: str, names: tuple[str, ...]) -> Transition:
        td = self.mapping(td, path)
        source = self.choice(td.get("from"), f"{path}.from", names)
        target = self.choice(td.get("to"), f"{path}.to", names)
        if source == target:
            raise self.fail(f"{path}.to", "a transition must lead to another state")
        kind = self.choice(td.get("type"), f"{path}.type", TRANSITIONS.names())
        return TRANSITIONS[kind].from_yaml(self, td, path, source, target)
