"""What can be read can be written: every registered element kind reads back what it
writes (``from_yaml(to_yaml(x)) == x``), and so do whole skills, the shipped ones too.

The kinds come from the registries, so a new kind is checked as soon as it registers:
its case fails until :data:`DOCS` has a strategy for the documents a skill file may
give it. Documents are drawn valid (as a designer or the learner writes them) and read
by the loader, so each ``x`` is an element as the loader makes it.
"""

from __future__ import annotations

import dataclasses
import io
import itertools
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd.skill import (
    AXIS_NAMES,
    CONSTRAINTS,
    FIELDS,
    GRIPPER_ACTIONS,
    MAPPINGS,
    TRANSITIONS,
    Bundle,
    Field,
    GripperAction,
    Registry,
    TiltCone,
    bundle_from_skill,
    dump_skill,
    load_skill,
    skill_from_bundle,
    vector_field_model_to_bytes,
)
from tests.strategies import unit_quaternions

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted((ROOT / "skills").glob("*.yaml"))
REGISTRIES: tuple[Registry, ...] = (MAPPINGS, CONSTRAINTS, TRANSITIONS, FIELDS)
KINDS = [(registry, name) for registry in REGISTRIES for name in registry.names()]

EE_FRAMES = ("ee", "tip")  # the frames that move with the end-effector
ALL_FRAMES = (*EE_FRAMES, "object", "rim")


def number(lo: float = -1.0, hi: float = 1.0) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def vec3(lo: float = -1.0, hi: float = 1.0) -> st.SearchStrategy[list[float]]:
    return st.lists(number(lo, hi), min_size=3, max_size=3)


direction = vec3().filter(lambda v: float(np.linalg.norm(v)) > 1e-6)
rel_model = st.sampled_from(("m.json", "m.npz"))


@st.composite
def quaternion(draw) -> list[float]:
    """A unit quaternion, or one the loader accepts as unit (its norm within 1e-3)."""
    q = draw(unit_quaternions()) * draw(st.sampled_from((1.0, 1.0 + 5e-4, 1.0 - 5e-4)))
    return q.tolist()


def pose() -> st.SearchStrategy[list[float]]:
    return st.builds(lambda t, q: t + q, vec3(), quaternion())


@st.composite
def with_optional(draw, doc: dict[str, Any], **optional: st.SearchStrategy) -> dict[str, Any]:
    """``doc`` with each of the ``optional`` keys given or left to its default."""
    for key, strategy in optional.items():
        if draw(st.booleans()):
            doc[key] = draw(strategy)
    return doc


def _sorted_pair(pair: tuple) -> tuple:
    a, b = pair
    if isinstance(a, list):
        return [min(x, y) for x, y in zip(a, b, strict=True)], [max(x, y) for x, y in zip(a, b, strict=True)]
    return min(a, b), max(a, b)


# --- documents, one strategy per kind ---------------------------------------------------


@st.composite
def linear(draw) -> dict[str, Any]:
    doc: dict[str, Any] = {"type": "linear"}
    if draw(st.booleans()):
        k = draw(st.sampled_from((1, 2, 3, 6)))
        doc["matrix"] = draw(st.lists(st.lists(number(-2, 2), min_size=k, max_size=k), min_size=6,
                                      max_size=6).filter(lambda m: any(any(row) for row in m)))
    else:
        names = (*AXIS_NAMES, *(f"-{a}" for a in AXIS_NAMES), None)
        doc["axes"] = draw(st.lists(st.sampled_from(names), min_size=1, max_size=6)
                           .filter(lambda a: any(x is not None for x in a)))
    return draw(with_optional(doc, frame=st.sampled_from(ALL_FRAMES),
                              translation=st.sampled_from(("object", "frame")),
                              rotation=st.sampled_from(("frame", "object"))))


@st.composite
def vector_field(draw) -> dict[str, Any]:
    return draw(with_optional(
        {"type": "vector_field", "model": draw(rel_model)},
        frame=st.sampled_from(EE_FRAMES), mode=st.sampled_from(("scale", "blend")),
        combine=st.sampled_from(("most_probable", "weighted", "intent")),
        intent_kappa=number(0, 50), min_v=number(0, 1), k_s=number(-0.99, 0.99),
        max_n=st.integers(1, 20), max_d=number(1e-6, 1), blend=number(0, 10),
        motion=st.sampled_from(("translate", "rigid"))))


@st.composite
def tilt_cone(draw) -> dict[str, Any]:
    return draw(with_optional({"type": "tilt_cone", "max_angle": draw(number(0, np.pi))},
                              frame=st.sampled_from(EE_FRAMES), axis=direction, reference=direction))


@st.composite
def band(draw) -> dict[str, Any]:
    lower, upper = _sorted_pair(draw(st.tuples(number(), number())))
    return draw(with_optional({"type": "band", "lower": lower, "upper": upper},
                              frame=st.sampled_from(EE_FRAMES), normal=direction, point=vec3()))


@st.composite
def box(draw) -> dict[str, Any]:
    lower, upper = _sorted_pair(draw(st.tuples(vec3(), vec3())))
    return draw(with_optional({"type": "box", "lower": lower, "upper": upper},
                              frame=st.sampled_from(EE_FRAMES)))


@st.composite
def neighbour_orientation(draw) -> dict[str, Any]:
    return draw(with_optional(
        {"type": "neighbour_orientation", "model": draw(rel_model)},
        frame=st.sampled_from(EE_FRAMES), max_n=st.integers(1, 20), max_d=number(1e-6, 1),
        pivot=st.none() | vec3(), rotation_weight=number(0, 10)))


@st.composite
def speed_near(draw) -> dict[str, Any]:
    return draw(with_optional(
        {"type": "speed_near", "within": draw(number(1e-6, 2)), "max_linear_speed": draw(number(1e-6, 1)),
         "max_angular_speed": draw(number(1e-6, 3))},
        frame=st.sampled_from(EE_FRAMES), point=st.none() | vec3(-0.5, 0.5)))


def transition(kind: str, **optional: st.SearchStrategy) -> st.SearchStrategy[dict[str, Any]]:
    return with_optional({"from": "a", "to": "b", "type": kind}, margin=number(0, 1), **optional)


@st.composite
def distance(draw) -> dict[str, Any]:
    doc = draw(transition("distance", frame=st.sampled_from(EE_FRAMES), point=vec3()))
    doc[draw(st.sampled_from(("below", "above")))] = draw(number(0, 1))
    return doc


@st.composite
def timeout(draw) -> dict[str, Any]:
    return {"from": "a", "to": "b", "type": "timeout", "after": draw(number(0, 60))}


@st.composite
def gripper_action(draw) -> dict[str, Any]:
    """A state's ``gripper`` (sctd.skill.gripper): each action with what it needs, and
    the optional rest."""
    action = draw(st.sampled_from(GRIPPER_ACTIONS))
    doc: dict[str, Any] = {"action": action}
    if action == "close":
        doc["force"] = draw(number(1e-3, 1000))
    if action == "width":
        doc["width"] = draw(number(0, 0.5))
    return draw(with_optional(doc, width=number(0, 0.5), force=number(1e-3, 1000), speed=number(1e-3, 1)))


@st.composite
def field_doc(draw, kind: str, **parameters: st.SearchStrategy) -> dict[str, Any]:
    doc = {"type": kind, **{k: draw(s) for k, s in parameters.items()}}
    return draw(with_optional(doc, weight=number(0, 1), sigma=number(0, 3),
                              inliers=st.integers(0, 1000)))


@st.composite
def general(draw) -> dict[str, Any]:
    m = draw(st.integers(1, 8))
    rows = st.lists(vec3(), min_size=m, max_size=m)
    doc = draw(field_doc("general", centres=rows, directions=rows))
    return draw(with_optional(doc, bandwidth=number(1e-4, 0.1)))


DOCS: dict[str, st.SearchStrategy[dict[str, Any]]] = {
    "linear": linear(),
    "vector_field": vector_field(),
    "tilt_cone": tilt_cone(),
    "band": band(),
    "box": box(),
    "neighbour_orientation": neighbour_orientation(),
    "speed_near": speed_near(),
    "hyperplane": transition("hyperplane", frame=st.sampled_from(EE_FRAMES), offset=number())
    .flatmap(lambda d: st.builds(lambda n: d | {"normal": n}, direction)),
    "distance": distance(),
    "timeout": timeout(),
    "force": transition("force", axis=direction).flatmap(
        lambda d: st.builds(lambda a: d | {"above": a}, number(0, 50))),
    "button": with_optional({"from": "a", "to": "b", "type": "button"}, button=st.integers(0, 8)),
    "gripper": st.builds(lambda g: {"from": "a", "to": "b", "type": "gripper", "grasped": g}, st.booleans()),
    "translation": field_doc("translation", direction=direction),
    "cylinder": field_doc("cylinder", point=vec3(), axis=direction).flatmap(
        lambda d: with_optional(d, pivot=vec3())),
    "sphere": field_doc("sphere", centre=vec3()).flatmap(
        lambda d: with_optional(d, radius=number(0, 1), pivot=vec3())),
    "point": field_doc("point", point=vec3()),
    "general": general(),
}


@st.composite
def model_file(draw, rel: str) -> bytes:
    """A vector-field model file (JSON or .npz by ``rel``) as a learner or person writes it."""
    fields = draw(st.lists(st.sampled_from(FIELDS.names()).flatmap(lambda n: DOCS[n]),
                           min_size=1, max_size=3))
    n = draw(st.integers(1, 6))
    arrays = {"points": draw(st.lists(vec3(), min_size=n, max_size=n)),
              "quaternions": draw(st.lists(quaternion(), min_size=n, max_size=n)),
              "responsibilities": draw(st.lists(st.lists(number(0, 1), min_size=len(fields),
                                                         max_size=len(fields)), min_size=n, max_size=n))}
    if rel.endswith(".json"):
        return json.dumps({"fields": fields, **arrays}).encode()
    buf = io.BytesIO()
    np.savez_compressed(buf, fields=np.array(json.dumps(fields)),
                        **{k: np.array(v) for k, v in arrays.items()})
    return buf.getvalue()


# --- reading an element as the loader does ----------------------------------------------


@st.composite
def frames(draw) -> dict[str, Any]:
    return {"tip": {"parent": "ee", "pose": draw(pose())},
            "rim": {"parent": "object", "pose": draw(pose())}}


def skill_around(registry: Registry, doc: dict[str, Any], frames_doc: dict[str, Any]) -> dict[str, Any]:
    """A skill document holding the element ``doc`` of ``registry``: in state ``a`` (a
    mapping or constraint, with a button on to ``b``), or as the transition ``a -> b``."""
    states: dict[str, Any] = {"a": {}, "b": {}}
    transitions = [doc] if registry is TRANSITIONS else [{"from": "a", "to": "b", "type": "button"}]
    if registry is MAPPINGS:
        states["a"]["input_mapping"] = [doc]
    elif registry is CONSTRAINTS:
        states["a"]["active_constraints"] = [doc]
    return {"sctd_skill": 1, "name": "t", "object": "obj", "frames": frames_doc,
            "fsm": {"start": "a", "end": "b", "transitions": transitions}, "states": states}


def read(registry: Registry, doc: dict[str, Any], files: dict[str, bytes], frames_doc: dict[str, Any]) -> Any:
    """The element of ``registry`` the loader reads from ``doc`` (a field: from a model
    file's entry)."""
    if registry is FIELDS:
        return Field.from_yaml(doc, "fields[0]", "m.json")
    text = yaml.safe_dump(skill_around(registry, doc, frames_doc))
    skill = skill_from_bundle(Bundle("t.yaml", text, files))
    if registry is TRANSITIONS:
        return skill.transitions[0]
    state = skill.states[0]
    return state.input_mappings[0] if registry is MAPPINGS else state.active_constraints[0]


def written_files(element: Any) -> dict[str, bytes]:
    """The model files an element reads, as written from what it holds."""
    models = element.models() if hasattr(element, "models") else ()
    return {rel: vector_field_model_to_bytes(model, rel) for rel, model in models}


@pytest.mark.parametrize(("registry", "name"), KINDS, ids=[f"{r.kind}:{n}" for r, n in KINDS])
@settings(max_examples=40)
@given(data=st.data())
def test_every_kind_reads_back_what_it_writes(registry, name, data):
    """``from_yaml(to_yaml(x)) == x`` for an element ``x`` as the loader makes it, and the
    document written again is the same text."""
    assert name in DOCS, f"no document strategy for the {registry.kind} {name!r}: add one to DOCS"
    doc = data.draw(DOCS[name], label="document")
    rel = doc.get("model")
    files = {rel: data.draw(model_file(rel), label="model file")} if isinstance(rel, str) else {}
    frames_doc = data.draw(frames(), label="frames")
    x = read(registry, doc, files, frames_doc)
    assert type(x) is registry[name]
    back = read(registry, x.to_yaml(), written_files(x), frames_doc)
    assert back == x
    assert yaml.safe_dump(back.to_yaml()) == yaml.safe_dump(x.to_yaml())


# --- whole skills -----------------------------------------------------------------------


def element_of(registry: Registry) -> st.SearchStrategy[dict[str, Any]]:
    return st.sampled_from(registry.names()).flatmap(lambda n: DOCS[n])


@st.composite
def skill_docs(draw) -> tuple[dict[str, Any], dict[str, bytes]]:
    """A skill document of a few states, each with drawn mappings and constraints, and
    the model files they name."""
    names = ["a", "b", "c"][:draw(st.integers(1, 3))]
    states = {}
    for n in names:
        states[n] = draw(with_optional({}, input_mapping=st.lists(element_of(MAPPINGS), max_size=2),
                                       active_constraints=st.lists(element_of(CONSTRAINTS), max_size=2),
                                       gripper=gripper_action(),
                                       object=st.sampled_from(("mug", "tabletop", "world"))))
    chain = [draw(element_of(TRANSITIONS)) | {"from": a, "to": b} for a, b in itertools.pairwise(names)]
    doc = draw(with_optional(
        {"sctd_skill": 1, "name": "s", "object": draw(st.sampled_from(("mug", "world"))),
         "frames": draw(frames()),
         "fsm": draw(with_optional({"start": names[0], "end": names[-1], "transitions": chain},
                                   min_dwell=number(0, 60))),
         "states": states},
        description=st.text(max_size=20),
        limits=with_optional({}, max_linear_speed=number(1e-3, 1), max_angular_speed=number(1e-3, 3)),
        candidate_frames=st.lists(st.builds(lambda p: {"name": "c", "position": p}, vec3()), max_size=2)))
    rels = {item["model"] for s in states.values() for key in ("input_mapping", "active_constraints")
            for item in s.get(key, []) if "model" in item}
    return doc, {rel: draw(model_file(rel)) for rel in sorted(rels)}


def _same_skill(a, b) -> bool:
    """Equal but for ``id`` and ``source``, which are the bundle's, not the skill's."""
    return dataclasses.replace(a, id="", source="") == dataclasses.replace(b, id="", source="")


@settings(max_examples=60)
@given(drawn=skill_docs())
def test_a_skill_reads_back_what_it_writes(drawn):
    """``load(write(load(doc))) == load(doc)``, and writing is a fixed point."""
    doc, files = drawn
    skill = skill_from_bundle(Bundle("s.yaml", yaml.safe_dump(doc), files))
    written = bundle_from_skill(skill)
    back = skill_from_bundle(written)
    assert _same_skill(back, skill)
    again = bundle_from_skill(back)
    assert again.yaml_text == written.yaml_text and again.files == written.files


def test_the_shipped_skills_are_all_here():
    assert {p.name for p in SHIPPED} >= {"pour.yaml", "pour-vf.yaml", "pour-linear.yaml", "drawer.yaml",
                                         "drawer-vf.yaml", "teleop.yaml"}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_a_shipped_skill_reads_back_what_it_writes(path):
    """``load(write(load(f))) == load(f)``, and ``write(load(write(load(f))))`` is the same
    text and model files as ``write(load(f))``. (The shipped files are not rewritten:
    their ids are hashes of their text.)"""
    skill = load_skill(path)
    written = bundle_from_skill(skill)
    back = skill_from_bundle(written)
    assert _same_skill(back, skill)
    again = bundle_from_skill(back)
    assert again.yaml_text == written.yaml_text and again.files == written.files
    assert sorted(written.files) == sorted(skill.models())


def test_a_header_is_written_as_comments():
    skill = load_skill(ROOT / "skills" / "teleop.yaml")
    text = dump_skill(skill, "Learned skill.\n  s0: tx")
    assert text.startswith("# Learned skill.\n#   s0: tx\nsctd_skill: 1\n")
    assert _same_skill(skill_from_bundle(Bundle("t.yaml", text, {})), skill)


def test_elements_compare_by_value():
    """Every parameter counts, arrays by value (a dataclass's own == cannot compare them)."""
    def cone(axis, angle=0.1):
        return TiltCone(axis=np.array(axis), reference=np.array([0.0, 0.0, 1.0]), max_angle=angle)

    assert cone([0.0, 0.0, 1.0]) == cone([-0.0, 0.0, 1.0])
    assert cone([0.0, 0.0, 1.0]) != cone([0.0, 1e-12, 1.0])
    assert cone([0.0, 0.0, 1.0]) != cone([0.0, 0.0, 1.0], 0.2)
    assert dataclasses.replace(cone([0.0, 0.0, 1.0]), frame="tip") != cone([0.0, 0.0, 1.0])
    assert hash(cone([0.0, 0.0, 1.0])) == hash(cone([0.0, 0.0, 1.0]))


@settings(max_examples=60)
@given(doc=gripper_action())
def test_a_states_gripper_action_reads_back_what_it_writes(doc):
    """A state's ``gripper``: ``from_yaml(to_yaml(x)) == x`` as the loader reads it in a
    skill, and the document written again is the same text."""
    def state_a(gripper_doc):
        text = yaml.safe_dump({"sctd_skill": 1, "name": "t", "object": "obj",
                               "fsm": {"start": "a", "end": "b",
                                       "transitions": [{"from": "a", "to": "b", "type": "button"}]},
                               "states": {"a": {"gripper": gripper_doc}, "b": {}}})
        return skill_from_bundle(Bundle("t.yaml", text, {})).states[0].gripper

    x = state_a(doc)
    assert type(x) is GripperAction and x.action == doc["action"]
    back = state_a(x.to_yaml())
    assert back == x
    assert yaml.safe_dump(back.to_yaml()) == yaml.safe_dump(x.to_yaml())
