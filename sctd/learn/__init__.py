"""Learning Shared Control Templates from demonstrations (thesis Ch. 4).

Pure numpy/scipy/scikit-learn/PyMaxflow: no Zenoh, no file I/O inside estimators.
Linear input mappings (Ch. 4.1): :class:`LinearIMLearner`, :func:`alpha_beta_swap`,
:func:`alpha_expansion`, :func:`energy`. Vector fields (Ch. 4.2):
:class:`VectorFieldLearner`. Demonstrations: :func:`read_demos`, :func:`dtw`.
End to end: :func:`learn_linear`, :func:`learn_vector_fields`, :func:`run_learn`.
"""

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
    write_demo_csv,
)
from .graphcut import alpha_beta_swap, alpha_expansion, energy
from .linear import (
    SELECTIONS,
    IMLabel,
    LinearIMLearner,
    im_costs,
    label_set,
    least_squares_command,
    neighbour_graph,
    selection_matrices,
    selection_matrix,
)
from .pipeline import (
    LearnParams,
    LinearResult,
    VectorFieldResult,
    learn_linear,
    learn_vector_fields,
    run_learn,
)
from .vf import VectorFieldLearner, ransac_iterations, unit_vectors

__all__ = [
    "SELECTIONS",
    "Demo",
    "DemoError",
    "IMLabel",
    "LearnParams",
    "LinearIMLearner",
    "LinearResult",
    "VectorFieldLearner",
    "VectorFieldResult",
    "alpha_beta_swap",
    "alpha_expansion",
    "dtw",
    "energy",
    "im_costs",
    "label_set",
    "learn_linear",
    "learn_vector_fields",
    "least_squares_command",
    "neighbour_graph",
    "ransac_iterations",
    "read_demo_csv",
    "read_demos",
    "run_learn",
    "selection_matrices",
    "selection_matrix",
    "smooth_poses",
    "spike_mask",
    "subsample_by_distance",
    "tf_distance",
    "unit_vectors",
    "write_demo_csv",
]
