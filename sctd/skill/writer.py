"""Skills -> skill files: the YAML document, its text, and the bundle with its model files.

The inverse of :mod:`sctd.skill.loader`. Each element writes itself (its ``to_yaml``,
every parameter exactly as it holds it); this module writes the skill's own parts (its
limits, frames, FSM and states) around them, and each vector-field model under the
file name its elements give. Loading what is written gives an equal skill, and writing
that again gives the same text (``tests/test_skill_yaml.py``). Nothing touches the
disk: ``sctd learn`` writes the bundle's files.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import yaml

from .frames import BUILTIN_FRAMES
from .loader import FORMAT_VERSION, Bundle
from .model import Skill, State
from .modelfile import vector_field_model_to_bytes


def skill_to_yaml(skill: Skill) -> dict[str, Any]:
    """The skill document (a dict for YAML) that :func:`~sctd.skill.loader.skill_from_bundle`
    reads back as an equal skill (but for its ``id`` and ``source``, which are the
    bundle's).

    Every setting is written, defaults too; what the format lets a file leave out when
    empty is left out: the description, frames beyond the built-in ``ee`` and
    ``object``, a state's own object, mappings, constraints or gripper action, the
    candidate frames, the region.
    """
    doc: dict[str, Any] = {"sctd_skill": FORMAT_VERSION, "name": skill.name}
    if skill.description:
        doc["description"] = skill.description
    doc["object"] = skill.object
    doc["limits"] = dataclasses.asdict(skill.limits)
    frames = {name: {"parent": f.parent, "pose": f.pose.tolist()}
              for name, f in skill.frames.items() if name not in BUILTIN_FRAMES}
    if frames:
        doc["frames"] = frames
    doc["fsm"] = {"start": skill.start, "end": skill.end, "min_dwell": skill.min_dwell,
                  "transitions": [t.to_yaml() for t in skill.transitions]}
    doc["states"] = {s.name: _state(s) for s in skill.states}
    if skill.candidate_frames:
        doc["candidate_frames"] = [dict(c) for c in skill.candidate_frames]
    if skill.region is not None:
        doc["region"] = skill.region.to_yaml()
    return doc


def _state(s: State) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if s.object is not None:
        out["object"] = s.object
    if s.input_mappings:
        out["input_mapping"] = [m.to_yaml() for m in s.input_mappings]
    if s.active_constraints:
        out["active_constraints"] = [c.to_yaml() for c in s.active_constraints]
    if s.gripper is not None:
        out["gripper"] = s.gripper.to_yaml()
    return out


def dump_skill(skill: Skill, header: str = "") -> str:
    """The skill file's text: ``header`` as comment lines, then :func:`skill_to_yaml`
    (block style, lists of scalars in flow style, folded near 100 characters)."""
    body = yaml.safe_dump(skill_to_yaml(skill), sort_keys=False, default_flow_style=None, width=100)
    return "".join(f"# {line}\n" for line in header.splitlines()) + body


def bundle_from_skill(skill: Skill, header: str = "") -> Bundle:
    """The skill as a bundle: ``<name>.yaml`` (:func:`dump_skill`) and the model file of
    each vector-field model its elements read, under the file name they give it (JSON or
    ``.npz`` by its suffix).

    Raises
    ------
    ValueError
        Two elements give one file name to different models.
    """
    files = {rel: vector_field_model_to_bytes(model, rel) for rel, model in skill.models().items()}
    return Bundle(name=f"{skill.name}.yaml", yaml_text=dump_skill(skill, header), files=files)
