"""Learning Shared Control Templates from demonstrations (thesis Ch. 4).

A plain library on numpy/scipy/scikit-learn/PyMaxflow: no Zenoh, no argument
parsing, no printing, nothing written to disk (``sctd learn`` in :mod:`sctd.cli.learn`
writes the skill files and the report). scikit-learn is imported when a linear-IM
learner first fits, not with this package.

From a notebook::

    from sctd.learn import learn, learn_skill, read_demos

    demos = read_demos("skills/demos/pour")
    skill = learn_skill(demos, method="linear", frames={"tip": [0, 0, 0.12, 0, 0, 0, 1]},
                        object="mug", smoothness=0.005, random_state=0)
    result = learn(demos, method="vf", random_state=0)  # learner, labels, timings
    result.learner.fields_

:func:`learn_skill` returns a validated :class:`sctd.skill.Skill`; :func:`learn` the
result with the fitted estimator; :func:`skill_bundle` turns a result into the YAML
text and model files. Hyperparameters are keyword arguments named as the fields of
:class:`Preprocessing`, :class:`LinearIMLearner` / :class:`VectorFieldLearner`,
:class:`SkillOptions` and :class:`VectorFieldOptions` (:func:`hyperparameter_names`);
each is defined once there, with the help text the command line shows.

The parts: demonstrations (:func:`read_demos`, :func:`dtw`, preprocessing); linear IMs
(Ch. 4.1: :class:`LinearIMLearner`, :func:`alpha_beta_swap`, :func:`alpha_expansion`,
:func:`energy`); vector fields (Ch. 4.2: :class:`VectorFieldLearner`); end to end
(:func:`learn_linear`, :func:`learn_vector_fields`, :func:`learn`, :func:`learn_skill`);
scores against known phases (:func:`segmentation_accuracy`, :func:`field_kinds_by_phase`).
"""

from .bundle import skill_bundle
from .demos import (
    Demo,
    DemoError,
    dtw,
    read_demo_csv,
    read_demos,
    smooth_poses,
    spike_mask,
    subsample_by_distance,
    tf_distance,
)
from .graphcut import alpha_beta_swap, alpha_expansion, energy
from .gripper import GripperError, GripperOptions, GripperPlan, plan_gripper, with_gripper
from .linear import (
    SELECTIONS,
    IMLabel,
    LinearIMLearner,
    Progress,
    im_costs,
    label_set,
    least_squares_command,
    neighbour_graph,
    selection_matrices,
    selection_matrix,
)
from .metrics import field_kinds_by_phase, segmentation_accuracy
from .objects import ObjectChoice, candidate_bodies, choose_objects
from .params import HyperparameterError, get_params, hyperparameter
from .pipeline import (
    METHODS,
    STAGES,
    check_hyperparameters,
    hyperparameter_names,
    learn,
    learn_linear,
    learn_skill,
    learn_vector_fields,
)
from .preprocess import Prepared, Preprocessing
from .results import LinearResult, SkillOptions, VectorFieldOptions, VectorFieldResult
from .traps import TrapError, TrapFinding
from .vf import VectorFieldLearner, ransac_iterations, unit_vectors

__all__ = [
    "METHODS",
    "SELECTIONS",
    "STAGES",
    "Demo",
    "DemoError",
    "GripperError",
    "GripperOptions",
    "GripperPlan",
    "HyperparameterError",
    "IMLabel",
    "LinearIMLearner",
    "LinearResult",
    "ObjectChoice",
    "Prepared",
    "Preprocessing",
    "Progress",
    "SkillOptions",
    "TrapError",
    "TrapFinding",
    "VectorFieldLearner",
    "VectorFieldOptions",
    "VectorFieldResult",
    "alpha_beta_swap",
    "alpha_expansion",
    "candidate_bodies",
    "check_hyperparameters",
    "choose_objects",
    "dtw",
    "energy",
    "field_kinds_by_phase",
    "get_params",
    "hyperparameter",
    "hyperparameter_names",
    "im_costs",
    "label_set",
    "learn",
    "learn_linear",
    "learn_skill",
    "learn_vector_fields",
    "least_squares_command",
    "neighbour_graph",
    "plan_gripper",
    "ransac_iterations",
    "read_demo_csv",
    "read_demos",
    "segmentation_accuracy",
    "selection_matrices",
    "selection_matrix",
    "skill_bundle",
    "smooth_poses",
    "spike_mask",
    "subsample_by_distance",
    "tf_distance",
    "unit_vectors",
    "with_gripper",
]
