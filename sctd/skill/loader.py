"""Skill files: YAML + model files -> validated :class:`~sctd.skill.model.Skill`.

Every skill travels as a :class:`Bundle` (the YAML text plus the model files it names,
by relative path); loading from disk first builds the bundle, so a skill from a file
and a skill from the hot-swap query go through the same validation. Errors read
``file: path.to.field: what is wrong``. Model files are JSON or pickle-free ``.npz``.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import posixpath
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import yaml

from .. import se3
from .errors import SkillError
from .model import (
    AXIS_NAMES,
    BUILTIN_FRAMES,
    Band,
    Box,
    Field,
    Frame,
    Limits,
    LinearMapping,
    NeighbourOrientation,
    Skill,
    State,
    TiltCone,
    Transition,
    VectorFieldMapping,
    VectorFieldModel,
)

FORMAT_VERSION = 1
BUNDLE_FORMAT = "sctd-skill-bundle"
# A packed bundle's largest size. The runtime copies a hot-swap payload once while it
# holds the GIL (0.25-1 ms per MB on the development VM), so this bounds what a swap can
# cost the tick; a vector-field model of 20k demonstration points is 1.4 MB compressed.
MAX_BUNDLE_BYTES = 8 * 1024 * 1024
MAX_TEXT = 10_000  # characters of a skill's name or description
MAX_MODEL_BYTES = 256 * 1024 * 1024  # arrays of one .npz model file, uncompressed


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
            _check_relative(name, f"files[{rel!r}]", rel)
        return cls(name=name, yaml_text=text, files=files)


def bundle_from_file(path: str | Path) -> Bundle:
    """Read a skill YAML and every model file it references (relative to the YAML)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise SkillError(str(path), "", f"cannot read ({exc.strerror})") from None
    doc = _parse_yaml(str(path), text)
    files: dict[str, bytes] = {}
    for where, rel in _model_references(doc):
        _check_relative(str(path), where, rel)
        target = path.parent / rel
        try:
            files[rel] = target.read_bytes()
        except OSError as exc:
            raise SkillError(str(path), where, f"model file {rel!r}: {exc.strerror}") from None
    return Bundle(name=str(path), yaml_text=text, files=files)


def load_skill(path: str | Path) -> Skill:
    """Load and validate a skill file (and its model files)."""
    return skill_from_bundle(bundle_from_file(path))


def skill_from_bundle(bundle: Bundle) -> Skill:
    """Validate a bundle into a Skill; nothing is read from disk."""
    doc = _parse_yaml(bundle.name, bundle.yaml_text)
    return _Parser(bundle).skill(doc)


# --- parsing --------------------------------------------------------------------------


class _StrictLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """Safe YAML (libyaml's parser where present) that refuses duplicate mapping keys:
    plain YAML loaders keep the last of two equal keys, silently."""


def _mapping_without_duplicates(loader: Any, node: yaml.MappingNode, deep: bool = False) -> Any:
    loader.flatten_mapping(node)
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            duplicate = key in seen
            seen.add(key)
        except TypeError:  # unhashable: construct_mapping names it
            continue
        if duplicate:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping", node.start_mark, f"duplicate key {key!r}",
                key_node.start_mark)
    return loader.construct_mapping(node, deep=deep)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                              _mapping_without_duplicates)


def _parse_yaml(file: str, text: str) -> Any:
    try:
        return yaml.load(text, Loader=_StrictLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else ""
        raise SkillError(file, where, f"invalid YAML ({getattr(exc, 'problem', exc)})") from None
    except RecursionError:
        raise SkillError(file, "", "invalid YAML (nested too deeply)") from None


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


def _check_relative(file: str, where: str, rel: str) -> None:
    norm = posixpath.normpath(rel)
    if (not rel or rel.startswith("/") or norm == "." or norm == ".." or norm.startswith("../")
            or "\\" in rel or "\0" in rel):
        raise SkillError(file, where, f"model path {rel!r} must be relative, inside the skill dir")


class _Parser:
    """Walks the YAML document, checking each field and naming its path on error."""

    def __init__(self, bundle: Bundle):
        self.bundle = bundle
        self.file = bundle.name
        self._models: dict[str, VectorFieldModel] = {}

    def fail(self, path: str, problem: str) -> SkillError:
        return SkillError(self.file, path, problem)

    # scalar and array checks
    def mapping(self, v: Any, path: str) -> dict:
        if not isinstance(v, dict):
            raise self.fail(path, f"expected a mapping, got {_kind(v)}")
        return v

    def known_keys(self, d: dict, path: str, allowed: set[str]) -> None:
        extra = sorted(set(map(str, d)) - allowed)
        if extra:
            raise self.fail(f"{path}.{extra[0]}", f"unknown field (allowed: {', '.join(sorted(allowed))})")

    def string(self, v: Any, path: str) -> str:
        if not isinstance(v, str) or not v:
            raise self.fail(path, f"expected a non-empty string, got {_kind(v)}")
        return v

    def number(self, v: Any, path: str, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False) -> float:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.fail(path, f"expected a number, got {_kind(v)}")
        x = float(v)
        if not math.isfinite(x):
            raise self.fail(path, f"must be finite, got {x}")
        if lo is not None and (x < lo or (lo_open and x == lo)):
            raise self.fail(path, f"must be {'>' if lo_open else '>='} {lo}, got {x}")
        if hi is not None and x > hi:
            raise self.fail(path, f"must be <= {hi}, got {x}")
        return x

    def integer(self, v: Any, path: str, lo: int = 0) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(path, f"expected an integer, got {_kind(v)}")
        if v < lo:
            raise self.fail(path, f"must be >= {lo}, got {v}")
        return v

    def vector(self, v: Any, path: str, n: int, unit: bool = False) -> np.ndarray:
        if not isinstance(v, list | tuple) or len(v) != n:
            raise self.fail(path, f"expected a list of {n} numbers, got {_kind(v)}")
        out = np.array([self.number(x, f"{path}[{i}]") for i, x in enumerate(v)])
        if unit:
            norm = float(np.linalg.norm(out))
            if norm < 1e-9:
                raise self.fail(path, "direction of zero length")
            out = out / norm
        return out

    def pose(self, v: Any, path: str) -> np.ndarray:
        p = self.vector(v, path, 7)
        n = float(np.linalg.norm(p[3:]))
        if abs(n - 1.0) > 1e-3:
            raise self.fail(path, f"quaternion [qx, qy, qz, qw] must be unit, has norm {n:.6f}")
        return se3.transform_from_pose(p)

    def choice(self, v: Any, path: str, options: tuple[str, ...]) -> str:
        if v not in options:
            raise self.fail(path, f"expected one of {', '.join(options)}, got {v!r}")
        return v

    # the document
    def skill(self, doc: Any) -> Skill:
        doc = self.mapping(doc, "")
        self.known_keys(doc, "", {"sctd_skill", "name", "description", "object", "limits",
                                  "frames", "fsm", "states", "candidate_frames"})
        version = doc.get("sctd_skill")
        if version != FORMAT_VERSION:
            raise self.fail("sctd_skill", f"expected format version {FORMAT_VERSION}, got {version!r}")
        name = self.string(doc.get("name"), "name")
        obj = self.string(doc.get("object"), "object")
        description = doc.get("description", "")
        if not isinstance(description, str):
            raise self.fail("description", "expected a string")
        for key, text in (("name", name), ("description", description)):
            if len(text) > MAX_TEXT:
                raise self.fail(key, f"{len(text)} characters, at most {MAX_TEXT}")

        limits = Limits()
        if "limits" in doc:
            ld = self.mapping(doc["limits"], "limits")
            self.known_keys(ld, "limits", {"max_linear_speed", "max_angular_speed"})
            limits = Limits(
                max_linear_speed=self.number(ld.get("max_linear_speed", limits.max_linear_speed),
                                             "limits.max_linear_speed", 0.0, 1.0, lo_open=True),
                max_angular_speed=self.number(ld.get("max_angular_speed", limits.max_angular_speed),
                                              "limits.max_angular_speed", 0.0, 3.0, lo_open=True),
            )

        frames = {n: Frame(n, n, np.eye(4)) for n in BUILTIN_FRAMES}  # type: ignore[arg-type]
        for fname, fd in (self.mapping(doc.get("frames") or {}, "frames")).items():
            path = f"frames.{fname}"
            if fname in BUILTIN_FRAMES:
                raise self.fail(path, f"{fname!r} is built in and cannot be redefined")
            fd = self.mapping(fd, path)
            self.known_keys(fd, path, {"parent", "pose"})
            parent = self.choice(fd.get("parent"), f"{path}.parent", BUILTIN_FRAMES)
            frames[str(fname)] = Frame(str(fname), parent, self.pose(fd.get("pose"), f"{path}.pose"))  # type: ignore[arg-type]

        states_doc = self.mapping(doc.get("states"), "states")
        if not states_doc:
            raise self.fail("states", "a skill needs at least one state")
        states = tuple(self.state(str(n), s, frames) for n, s in states_doc.items())
        names = [s.name for s in states]

        fsm = self.mapping(doc.get("fsm"), "fsm")
        self.known_keys(fsm, "fsm", {"start", "end", "transitions", "min_dwell"})
        start = self.choice(fsm.get("start"), "fsm.start", tuple(names))
        end = self.choice(fsm.get("end"), "fsm.end", tuple(names))
        min_dwell = self.number(fsm.get("min_dwell", 0.05), "fsm.min_dwell", 0.0, 60.0)
        tdoc = fsm.get("transitions") or []
        if not isinstance(tdoc, list):
            raise self.fail("fsm.transitions", f"expected a list, got {_kind(tdoc)}")
        transitions = tuple(
            self.transition(t, f"fsm.transitions[{i}]", tuple(names), frames)
            for i, t in enumerate(tdoc)
        )
        self.check_reachable(start, end, names, transitions)

        cands = doc.get("candidate_frames") or []
        if not isinstance(cands, list):
            raise self.fail("candidate_frames", "expected a list")
        for i, c in enumerate(cands):
            c = self.mapping(c, f"candidate_frames[{i}]")
            self.string(c.get("name"), f"candidate_frames[{i}].name")
            self.vector(c.get("position"), f"candidate_frames[{i}].position", 3)

        return Skill(
            name=name, object=obj, frames=frames, states=states, transitions=transitions,
            start=start, end=end, limits=limits, min_dwell=min_dwell, description=description,
            id=self.bundle.id, source=self.file, candidate_frames=tuple(cands),
        )

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

    def frame_ref(self, v: Any, path: str, frames: dict[str, Frame]) -> str:
        name = self.string(v, path)
        if name not in frames:
            raise self.fail(path, f"unknown frame {name!r} (known: {', '.join(frames)})")
        return name

    def ee_frame_ref(self, v: Any, path: str, frames: dict[str, Frame]) -> str:
        name = self.frame_ref(v, path, frames)
        if frames[name].parent != "ee" and name != "ee":
            raise self.fail(path, f"frame {name!r} must move with the end-effector (parent: ee)")
        return name

    def state(self, name: str, sd: Any, frames: dict[str, Frame]) -> State:
        path = f"states.{name}"
        sd = self.mapping(sd if sd is not None else {}, path)
        self.known_keys(sd, path, {"input_mapping", "active_constraints"})
        ims = sd.get("input_mapping") or []
        acs = sd.get("active_constraints") or []
        if not isinstance(ims, list):
            raise self.fail(f"{path}.input_mapping", f"expected a list, got {_kind(ims)}")
        if not isinstance(acs, list):
            raise self.fail(f"{path}.active_constraints", f"expected a list, got {_kind(acs)}")
        return State(
            name=name,
            input_mappings=tuple(self.input_mapping(m, f"{path}.input_mapping[{i}]", frames)
                                 for i, m in enumerate(ims)),
            active_constraints=tuple(self.constraint(c, f"{path}.active_constraints[{i}]", frames)
                                     for i, c in enumerate(acs)),
        )

    def input_mapping(self, md: Any, path: str, frames: dict[str, Frame]):
        md = self.mapping(md, path)
        kind = self.choice(md.get("type"), f"{path}.type", ("linear", "vector_field"))
        if kind == "linear":
            self.known_keys(md, path, {"type", "frame", "matrix", "axes", "translation", "rotation"})
            frame = self.frame_ref(md.get("frame", "ee"), f"{path}.frame", frames)
            if "matrix" in md and "axes" in md:
                raise self.fail(path, "give either matrix or axes, not both")
            if "matrix" in md:
                matrix = self.matrix(md["matrix"], f"{path}.matrix")
            elif "axes" in md:
                matrix = self.axes(md["axes"], f"{path}.axes")
            else:
                raise self.fail(path, "a linear mapping needs matrix (6 rows) or axes")
            translation = self.choice(md.get("translation", "object"), f"{path}.translation",
                                      ("object", "frame"))
            rotation = self.choice(md.get("rotation", "frame"), f"{path}.rotation", ("frame", "object"))
            return LinearMapping(frame=frame, matrix=matrix, translation=translation,  # type: ignore[arg-type]
                                 rotation=rotation)  # type: ignore[arg-type]
        self.known_keys(md, path, {"type", "model", "frame", "mode", "combine", "min_v", "k_s",
                                   "max_n", "max_d", "blend", "motion", "intent_kappa"})
        model_file = self.string(md.get("model"), f"{path}.model")
        return VectorFieldMapping(
            model_file=model_file,
            model=self.model(model_file, f"{path}.model"),
            frame=self.ee_frame_ref(md.get("frame", "ee"), f"{path}.frame", frames),
            mode=self.choice(md.get("mode", "scale"), f"{path}.mode", ("scale", "blend")),  # type: ignore[arg-type]
            combine=self.choice(md.get("combine", "weighted"), f"{path}.combine",  # type: ignore[arg-type]
                                ("most_probable", "weighted", "intent")),
            intent_kappa=self.number(md.get("intent_kappa", 4.0), f"{path}.intent_kappa", 0.0, 50.0),
            min_v=self.number(md.get("min_v", 0.1), f"{path}.min_v", 0.0, 1.0),
            k_s=self.number(md.get("k_s", 0.5), f"{path}.k_s", -0.99, 0.99),
            max_n=self.integer(md.get("max_n", 5), f"{path}.max_n", 1),
            max_d=self.number(md.get("max_d", 0.15), f"{path}.max_d", 0.0, lo_open=True),
            blend=self.number(md.get("blend", 0.5), f"{path}.blend", 0.0, 10.0),
            motion=self.choice(md.get("motion", "translate"), f"{path}.motion",  # type: ignore[arg-type]
                               ("translate", "rigid")),
        )

    def matrix(self, v: Any, path: str) -> np.ndarray:
        if not isinstance(v, list) or len(v) != 6:
            raise self.fail(path, f"expected 6 rows (tx, ty, tz, rx, ry, rz), got {_kind(v)}")
        rows = []
        width = None
        for i, row in enumerate(v):
            if not isinstance(row, list) or not row:
                raise self.fail(f"{path}[{i}]", f"expected a list of numbers, got {_kind(row)}")
            if width is None:
                width = len(row)
            elif len(row) != width:
                raise self.fail(f"{path}[{i}]", f"expected {width} columns like row 0, got {len(row)}")
            rows.append([self.number(x, f"{path}[{i}][{j}]") for j, x in enumerate(row)])
        if width not in (1, 2, 3, 6):
            raise self.fail(path, f"expected 1, 2, 3 or 6 input columns, got {width}")
        m = np.array(rows)
        if not np.any(m):
            raise self.fail(path, "all-zero matrix maps every input to nothing")
        return m

    def axes(self, v: Any, path: str) -> np.ndarray:
        if not isinstance(v, list) or not 1 <= len(v) <= 6:
            raise self.fail(path, f"expected a list of 1-6 axis names, got {_kind(v)}")
        m = np.zeros((6, len(v)))
        for j, a in enumerate(v):
            if a is None:
                continue
            sign = 1.0
            if isinstance(a, str) and a.startswith("-"):
                sign, a = -1.0, a[1:]
            if a not in AXIS_NAMES:
                raise self.fail(f"{path}[{j}]", f"expected one of {', '.join(AXIS_NAMES)} "
                                f"(optionally with '-') or null, got {a!r}")
            m[AXIS_NAMES.index(a), j] = sign
        if not np.any(m):
            raise self.fail(path, "no axis selected")
        return m

    def constraint(self, cd: Any, path: str, frames: dict[str, Frame]):
        cd = self.mapping(cd, path)
        kind = self.choice(cd.get("type"), f"{path}.type",
                           ("tilt_cone", "band", "box", "neighbour_orientation"))
        if kind == "tilt_cone":
            self.known_keys(cd, path, {"type", "frame", "axis", "reference", "max_angle"})
            return TiltCone(
                frame=self.ee_frame_ref(cd.get("frame", "ee"), f"{path}.frame", frames),
                axis=self.vector(cd.get("axis", [0, 0, 1]), f"{path}.axis", 3, unit=True),
                reference=self.vector(cd.get("reference", [0, 0, 1]), f"{path}.reference", 3, unit=True),
                max_angle=self.number(cd.get("max_angle"), f"{path}.max_angle", 0.0, math.pi),
            )
        if kind == "band":
            self.known_keys(cd, path, {"type", "frame", "normal", "point", "lower", "upper"})
            lower = self.number(cd.get("lower"), f"{path}.lower")
            upper = self.number(cd.get("upper"), f"{path}.upper")
            if upper < lower:
                raise self.fail(f"{path}.upper", f"must be >= lower ({lower}), got {upper}")
            return Band(
                frame=self.ee_frame_ref(cd.get("frame", "ee"), f"{path}.frame", frames),
                normal=self.vector(cd.get("normal", [0, 0, 1]), f"{path}.normal", 3, unit=True),
                point=self.vector(cd.get("point", [0, 0, 0]), f"{path}.point", 3),
                lower=lower, upper=upper,
            )
        if kind == "box":
            self.known_keys(cd, path, {"type", "frame", "lower", "upper"})
            box_lo = self.vector(cd.get("lower"), f"{path}.lower", 3)
            box_hi = self.vector(cd.get("upper"), f"{path}.upper", 3)
            if np.any(box_hi < box_lo):
                raise self.fail(f"{path}.upper", "every upper bound must be >= its lower bound")
            return Box(frame=self.ee_frame_ref(cd.get("frame", "ee"), f"{path}.frame", frames),
                       lower=box_lo, upper=box_hi)
        self.known_keys(cd, path, {"type", "model", "frame", "max_n", "max_d", "pivot", "rotation_weight"})
        model_file = self.string(cd.get("model"), f"{path}.model")
        return NeighbourOrientation(
            model_file=model_file,
            model=self.model(model_file, f"{path}.model"),
            frame=self.ee_frame_ref(cd.get("frame", "ee"), f"{path}.frame", frames),
            max_n=self.integer(cd.get("max_n", 5), f"{path}.max_n", 1),
            max_d=self.number(cd.get("max_d", 0.15), f"{path}.max_d", 0.0, lo_open=True),
            pivot=None if cd.get("pivot") is None else self.vector(cd["pivot"], f"{path}.pivot", 3),
            rotation_weight=self.number(cd.get("rotation_weight", 0.0), f"{path}.rotation_weight", 0.0, 10.0),
        )

    def transition(self, td: Any, path: str, names: tuple[str, ...],
                   frames: dict[str, Frame]) -> Transition:
        td = self.mapping(td, path)
        source = self.choice(td.get("from"), f"{path}.from", names)
        target = self.choice(td.get("to"), f"{path}.to", names)
        if source == target:
            raise self.fail(f"{path}.to", "a transition must lead to another state")
        kind = self.choice(td.get("type"), f"{path}.type",
                           ("hyperplane", "distance", "timeout", "force", "button"))
        common = {"from", "to", "type", "margin"}
        if kind == "hyperplane":
            self.known_keys(td, path, common | {"frame", "normal", "offset"})
            normal = self.vector(td.get("normal"), f"{path}.normal", 3)
            norm = float(np.linalg.norm(normal))
            if norm < 1e-12:
                raise self.fail(f"{path}.normal", "normal of zero length")
            offset = self.number(td.get("offset", 0.0), f"{path}.offset")
            return Transition(source, target, "hyperplane",
                              frame=self.ee_frame_ref(td.get("frame", "ee"), f"{path}.frame", frames),
                              normal=normal / norm, offset=offset / norm,
                              margin=self.number(td.get("margin", 0.005), f"{path}.margin", 0.0))
        if kind == "distance":
            self.known_keys(td, path, common | {"frame", "point", "below", "above"})
            if ("below" in td) == ("above" in td):
                raise self.fail(path, "a distance transition needs exactly one of below, above")
            direction = "below" if "below" in td else "above"
            return Transition(source, target, "distance",
                              frame=self.ee_frame_ref(td.get("frame", "ee"), f"{path}.frame", frames),
                              point=self.vector(td.get("point", [0, 0, 0]), f"{path}.point", 3),
                              threshold=self.number(td[direction], f"{path}.{direction}", 0.0),
                              direction=direction,  # type: ignore[arg-type]
                              margin=self.number(td.get("margin", 0.005), f"{path}.margin", 0.0))
        if kind == "button":
            self.known_keys(td, path, common | {"button"})
            return Transition(source, target, "button",
                              button=self.integer(td.get("button", 0), f"{path}.button", 0))
        if kind == "timeout":
            self.known_keys(td, path, common | {"after"})
            return Transition(source, target, "timeout",
                              threshold=self.number(td.get("after"), f"{path}.after", 0.0))
        self.known_keys(td, path, common | {"above", "axis"})
        axis = td.get("axis")
        return Transition(source, target, "force",
                          threshold=self.number(td.get("above"), f"{path}.above", 0.0),
                          axis=None if axis is None else self.vector(axis, f"{path}.axis", 3, unit=True),
                          margin=self.number(td.get("margin", 1.0), f"{path}.margin", 0.0))

    def model(self, rel: str, path: str) -> VectorFieldModel:
        _check_relative(self.file, path, rel)
        if rel in self._models:
            return self._models[rel]
        if rel not in self.bundle.files:
            raise self.fail(path, f"model file {rel!r} is missing")
        where = posixpath.join(posixpath.dirname(self.file), rel)
        model = vector_field_model_from_bytes(self.bundle.files[rel], rel, where)
        self._models[rel] = model
        return model


# --- model files ----------------------------------------------------------------------


def vector_field_model_from_bytes(data: bytes, rel: str, where: str) -> VectorFieldModel:
    """Parse a vector-field model file (``.json`` or pickle-free ``.npz``)."""
    if rel.endswith(".json"):
        try:
            doc = json.loads(data)
        except (ValueError, UnicodeDecodeError) as exc:
            raise SkillError(where, "", f"invalid JSON ({exc})") from None
        except RecursionError:
            raise SkillError(where, "", "invalid JSON (nested too deeply)") from None
        if not isinstance(doc, dict):
            raise SkillError(where, "", "expected a JSON object")
        fields_doc = doc.get("fields")
        arrays = {k: doc.get(k) for k in ("points", "quaternions", "responsibilities")}
    elif rel.endswith(".npz"):
        arrays, fields_doc = _npz_arrays(data, where)
    else:
        raise SkillError(where, "", "model files must be .json or .npz")

    def array(key: str, cols: int) -> np.ndarray:
        try:
            a = np.asarray(arrays.get(key), dtype=float)
        except (TypeError, ValueError):
            raise SkillError(where, key, "expected a numeric array") from None
        if a.ndim != 2 or a.shape[1] != cols:
            raise SkillError(where, key, f"expected shape (n, {cols}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            row = int(np.argwhere(~np.isfinite(a))[0, 0])
            raise SkillError(where, f"{key}[{row}]", "not finite")
        return a

    if not isinstance(fields_doc, list) or not fields_doc:
        raise SkillError(where, "fields", "expected a non-empty list of fields")
    fields = tuple(_field(f, f"fields[{i}]", where) for i, f in enumerate(fields_doc))
    points = array("points", 3)
    quats = array("quaternions", 4)
    resp = array("responsibilities", len(fields))
    if not (len(points) == len(quats) == len(resp)) or len(points) == 0:
        raise SkillError(where, "points", "points, quaternions and responsibilities need the "
                         f"same non-zero length, got {len(points)}, {len(quats)}, {len(resp)}")
    norms = np.linalg.norm(quats, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
    if len(bad):
        raise SkillError(where, f"quaternions[{bad[0]}]", f"not unit (norm {norms[bad[0]]:.6f})")
    return VectorFieldModel(fields=fields, points=points, quaternions=quats / norms[:, None],
                            responsibilities=resp)


def _npz_arrays(data: bytes, where: str) -> tuple[dict[str, Any], Any]:
    """The arrays and the ``fields`` document of a pickle-free .npz model file."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            size = sum(info.file_size for info in zf.infolist())
        if size > MAX_MODEL_BYTES:
            raise SkillError(where, "", f"model file inflates to {size} bytes (at most {MAX_MODEL_BYTES})")
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            arrays = {k: z[k] for k in ("points", "quaternions", "responsibilities") if k in z}
            fields_doc = json.loads(str(z["fields"])) if "fields" in z else None
    except SkillError:
        raise
    except RecursionError:
        raise SkillError(where, "fields", "invalid JSON (nested too deeply)") from None
    except Exception as exc:  # zipfile, zlib and numpy raise many unrelated types on bad bytes
        raise SkillError(where, "", f"not a pickle-free npz model file ({type(exc).__name__}: "
                         f"{str(exc)[:200]})") from None
    return arrays, fields_doc


def _field(fd: Any, path: str, where: str) -> Field:
    if not isinstance(fd, dict):
        raise SkillError(where, path, "expected a mapping")
    kind = fd.get("type")

    def vec(key: str, unit: bool = False) -> np.ndarray:
        v = fd.get(key)
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise SkillError(where, f"{path}.{key}", f"expected 3 finite numbers, got {v!r}")
        if unit:
            n = float(np.linalg.norm(a))
            if n < 1e-9:
                raise SkillError(where, f"{path}.{key}", "direction of zero length")
            a = a / n
        return a

    def num(key: str, default: float) -> float:
        v = fd.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
            raise SkillError(where, f"{path}.{key}", f"expected a finite number >= 0, got {v!r}")
        return float(v)

    weight, sigma, inliers = num("weight", 1.0), num("sigma", 0.3), int(num("inliers", 0))
    if kind == "translation":
        return Field("translation", weight, sigma, inliers, direction=vec("direction", unit=True))
    pivot = None if fd.get("pivot") is None else vec("pivot")
    if kind == "cylinder":
        return Field("cylinder", weight, sigma, inliers, point=vec("point"), axis=vec("axis", unit=True),
                     pivot=pivot)
    if kind == "sphere":
        radius = fd.get("radius")
        return Field("sphere", weight, sigma, inliers, centre=vec("centre"),
                     radius=None if radius is None else num("radius", 0.0), pivot=pivot)
    raise SkillError(where, f"{path}.type", f"expected translation, cylinder or sphere, got {kind!r}")


def _kind(v: Any) -> str:
    if v is None:
        return "nothing"
    if isinstance(v, list | tuple):
        return f"a list of {len(v)}"
    return type(v).__name__


def vector_field_model_to_bytes(model: VectorFieldModel, rel: str) -> bytes:
    """Serialise a model for a ``.json`` or pickle-free ``.npz`` model file."""
    from .summary import field_summary

    fields = [field_summary(f) for f in model.fields]
    if rel.endswith(".json"):
        return json.dumps({"fields": fields, "points": model.points.tolist(),
                           "quaternions": model.quaternions.tolist(),
                           "responsibilities": model.responsibilities.tolist()}).encode()
    if rel.endswith(".npz"):
        buf = io.BytesIO()
        np.savez_compressed(buf, fields=np.array(json.dumps(fields)), points=model.points,
                            quaternions=model.quaternions,
                            responsibilities=model.responsibilities)
        return buf.getvalue()
    raise ValueError(f"{rel}: model files must be .json or .npz")
