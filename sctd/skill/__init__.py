"""Skill model, YAML I/O, FSM, input mappings, active constraints, transitions.

Pure numpy/scipy: no Zenoh, no scikit-learn. See ``docs/skill-format.md``.

Each kind of element is one class in the module of its element kind, registered by
its ``type`` name: input mappings in :mod:`.mappings` (:data:`MAPPINGS`), active
constraints in :mod:`.constraints` (:data:`CONSTRAINTS`), transitions in
:mod:`.transitions` (:data:`TRANSITIONS`), vector fields in :mod:`.fields`
(:data:`FIELDS`). Each reads itself (``from_yaml``) and writes itself (``to_yaml``);
:mod:`.loader` reads a whole skill, :mod:`.writer` writes one.
"""

from .constraints import (
    CONSTRAINTS,
    ActiveConstraint,
    Band,
    Box,
    NeighbourOrientation,
    SpeedNear,
    StepLimit,
    TiltCone,
)
from .engine import SkillEngine
from .errors import SkillError
from .fields import FIELDS, CylinderField, Field, SphereField, TranslationField, sigmoid
from .frames import WORLD_OBJECT, Frame
from .gripper import GRIPPER_ACTIONS, GripperAction
from .loader import Bundle, bundle_from_file, load_skill, skill_from_bundle
from .mappings import AXIS_NAMES, MAPPINGS, InputMapping, LinearMapping, VectorFieldMapping
from .model import Limits, Skill, State
from .modelfile import VectorFieldModel, vector_field_model_from_bytes, vector_field_model_to_bytes
from .registry import Registry
from .stuck import StuckDetector
from .summary import field_summary, skill_summary
from .transitions import TRANSITIONS, Button, Distance, Force, Gripper, Hyperplane, Timeout, Transition
from .workspace import Workspace
from .writer import bundle_from_skill, dump_skill, skill_to_yaml

__all__ = [
    "AXIS_NAMES",
    "CONSTRAINTS",
    "FIELDS",
    "GRIPPER_ACTIONS",
    "MAPPINGS",
    "TRANSITIONS",
    "WORLD_OBJECT",
    "ActiveConstraint",
    "Band",
    "Box",
    "Bundle",
    "Button",
    "CylinderField",
    "Distance",
    "Field",
    "Force",
    "Frame",
    "Gripper",
    "GripperAction",
    "Hyperplane",
    "InputMapping",
    "Limits",
    "LinearMapping",
    "NeighbourOrientation",
    "Registry",
    "Skill",
    "SkillEngine",
    "SkillError",
    "SpeedNear",
    "SphereField",
    "State",
    "StepLimit",
    "StuckDetector",
    "TiltCone",
    "Timeout",
    "Transition",
    "TranslationField",
    "VectorFieldMapping",
    "VectorFieldModel",
    "Workspace",
    "bundle_from_file",
    "bundle_from_skill",
    "dump_skill",
    "field_summary",
    "load_skill",
    "sigmoid",
    "skill_from_bundle",
    "skill_summary",
    "skill_to_yaml",
    "vector_field_model_from_bytes",
    "vector_field_model_to_bytes",
]
