"""Skill model, YAML I/O, FSM, input mappings, active constraints, transitions.

Pure numpy/scipy: no Zenoh, no scikit-learn. See ``docs/skill-format.md``.
"""

from .engine import SkillEngine
from .errors import SkillError
from .fields import agreement, deviation_angles, field_vectors, guided_direction, sigmoid
from .loader import (
    Bundle,
    bundle_from_file,
    load_skill,
    skill_from_bundle,
    vector_field_model_from_bytes,
    vector_field_model_to_bytes,
)
from .model import (
    AXIS_NAMES,
    WORLD_OBJECT,
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
from .summary import field_summary, skill_summary

__all__ = [
    "AXIS_NAMES",
    "WORLD_OBJECT",
    "Band",
    "Box",
    "Bundle",
    "Field",
    "Frame",
    "Limits",
    "LinearMapping",
    "NeighbourOrientation",
    "Skill",
    "SkillEngine",
    "SkillError",
    "State",
    "TiltCone",
    "Transition",
    "VectorFieldMapping",
    "VectorFieldModel",
    "agreement",
    "bundle_from_file",
    "deviation_angles",
    "field_summary",
    "field_vectors",
    "guided_direction",
    "load_skill",
    "sigmoid",
    "skill_from_bundle",
    "skill_summary",
    "vector_field_model_from_bytes",
    "vector_field_model_to_bytes",
]
