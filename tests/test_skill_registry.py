"""The element registries: one class per kind, found by its ``type`` name."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pytest
import yaml

from sctd import se3
from sctd.skill import (
    CONSTRAINTS,
    FIELDS,
    MAPPINGS,
    TRANSITIONS,
    ActiveConstraint,
    Bundle,
    CylinderField,
    Field,
    SkillEngine,
    SkillError,
    SphereField,
    TranslationField,
    bundle_from_skill,
    skill_from_bundle,
    skill_summary,
)
from sctd.skill.reader import Reader
from sctd.skill.workspace import Workspace


def test_registries_hold_the_format_kinds_in_their_documented_order():
    """The order is the one the loader's "expected one of ..." messages list."""
    assert MAPPINGS.names() == ("linear", "vector_field")
    assert CONSTRAINTS.names() == ("tilt_cone", "band", "box", "neighbour_orientation", "speed_near")
    assert TRANSITIONS.names() == ("hyperplane", "distance", "timeout", "force", "button", "gripper")
    assert FIELDS.names() == ("translation", "cylinder", "sphere", "point", "general")
    for registry in (MAPPINGS, CONSTRAINTS, TRANSITIONS, FIELDS):
        assert all(registry[name].type == name for name in registry.names())


def test_a_type_name_is_taken_once():
    with pytest.raises(ValueError, match="already registered"):
        CONSTRAINTS.register(CONSTRAINTS["band"])


def _doc(constraint: dict) -> str:
    return yaml.safe_dump({
        "sctd_skill": 1, "name": "t", "object": "obj",
        "fsm": {"start": "s", "end": "s"},
        "states": {"s": {"input_mapping": [{"type": "linear", "axes": ["tx", "ty", "tz"]}],
                         "active_constraints": [constraint]}}})


def test_a_new_constraint_kind_is_one_class(monkeypatch):
    """Registering a class is all it takes for reading and writing skill files, the
    summary and the engine."""
    monkeypatch.setattr(CONSTRAINTS, "_classes", dict(CONSTRAINTS._classes))

    @CONSTRAINTS.register
    @dataclass(frozen=True, kw_only=True, eq=False)
    class Floor(ActiveConstraint):
        type: ClassVar[str] = "floor"
        height: float

        @classmethod
        def from_yaml(cls, r: Reader, cd: dict, path: str) -> Floor:
            r.known_keys(cd, path, {"type", "frame", "height"})
            return cls(frame=r.ee_frame_ref(cd.get("frame", "ee"), f"{path}.frame"),
                       height=r.number(cd.get("height"), f"{path}.height"))

        def to_yaml(self) -> dict[str, Any]:
            return {"type": self.type, "frame": self.frame, "height": self.height}

        def project(self, F: se3.Flat, G: se3.Flat, ws: Workspace) -> se3.Flat:
            return F if G[11] >= self.height else se3.translate_flat(F, 0.0, 0.0, self.height - G[11])

    skill = skill_from_bundle(Bundle("t.yaml", _doc({"type": "floor", "height": 0.05}), {}))
    assert skill_summary(skill)["states"][0]["active_constraints"] == [
        {"type": "floor", "frame": "ee", "height": 0.05}]
    floor = skill.states[0].active_constraints[0]
    back = skill_from_bundle(bundle_from_skill(skill)).states[0].active_constraints[0]
    assert back == floor and back != Floor(frame="ee", height=0.06)
    eng = SkillEngine(skill)
    F = se3.flat_from_pose([0.0, 0.0, 0.051, 0.0, 0.0, 0.0, 1.0])
    assert np.isclose(eng.command(F, (0.0, 0.0, -1.0), 0.1)[11], 0.05)
    where = r"t.yaml: states.s.active_constraints\[0\].height"
    with pytest.raises(SkillError, match=where + ": expected a number"):
        skill_from_bundle(Bundle("t.yaml", _doc({"type": "floor"}), {}))


def test_an_unknown_type_lists_the_registered_ones():
    with pytest.raises(SkillError) as e:
        skill_from_bundle(Bundle("t.yaml", _doc({"type": "cage"}), {}))
    assert str(e.value) == ("t.yaml: states.s.active_constraints[0].type: expected one of "
                            "tilt_cone, band, box, neighbour_orientation, speed_near, got 'cage'")
    with pytest.raises(SkillError, match=r"m.json: fields\[0\].type: expected translation, cylinder, "
                                         r"sphere, point or general, got 'torus'"):
        Field.from_yaml({"type": "torus"}, "fields[0]", "m.json")


def test_a_field_entry_with_an_unknown_key_is_refused_naming_it():
    """A misspelt parameter would silently take its default: it is refused, named."""
    with pytest.raises(SkillError, match=r"m.json: fields\[0\]\.pviot: unknown field of a sphere field "
                                         r"\(allowed: centre, inliers, pivot, pivot_within, radius, sigma, "
                                         r"type, weight\)"):
        Field.from_yaml({"type": "sphere", "centre": [0, 0, 0], "pviot": [0, 0, 0.1]}, "fields[0]", "m.json")
    with pytest.raises(SkillError, match=r"fields\[0\]\.radius: unknown field of a translation"):
        Field.from_yaml({"type": "translation", "direction": [1, 0, 0], "radius": 0.1}, "fields[0]", "m.json")
    f = Field.from_yaml({"type": "sphere", "centre": [0, 0, 0], "pivot": None}, "fields[0]", "m.json")
    assert f.pivot is None  # an optional key left unset is fine


@pytest.mark.parametrize("field", [
    TranslationField(direction=np.array([0.6, 0.0, 0.8]), weight=0.3, sigma=0.2, inliers=7),
    CylinderField(point=np.array([0.1, 0.0, 0.0]), axis=np.array([0.0, 0.6, 0.8]),
                  pivot=np.array([0.0, 0.0, 0.12])),
    SphereField(centre=np.array([0.05, -0.02, 0.1]), radius=0.12),
    SphereField(centre=np.array([0.05, -0.02, 0.1])),
])
def test_a_field_reads_back_what_it_writes(field):
    """What a model file stores of a field (its ``to_yaml``) reads back as the same field."""
    back = Field.from_yaml(field.to_yaml(), "fields[0]", "m.json")
    assert back == field and back.summary() == field.summary()
