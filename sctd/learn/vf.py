"""Vector fields from demonstrations (Ch. 4.2, Algorithms 4-6, Appendix A.1).

:class:`VectorFieldLearner` holds the hyperparameters and runs the pipeline, whose jobs
live in modules of their own:

1. Unit displacement vectors ``v = (p_{t+1} - p_t) / |p_{t+1} - p_t|`` (eq. 4.21) at
   the positions ``p_t`` of the demonstrations, and the least-squares fit of each field
   kind (:mod:`.vffields`).
2. Sequential RANSAC (Algorithm 5, :mod:`.vfransac`): for each field type a
   minimal-sample estimate scored by the angle inliers, refined by least squares on
   them; the best field kept, its inliers removed, ``n_fields`` times.
3. Model selection (:mod:`.vfselect`, with the direction mixtures of
   :mod:`.vfmixture`): by ``selection`` ``likelihood``, the shapes compete by BIC, and
   a general field may take the place of the last ones; by ``inliers``, the thesis'
   MSAC score.
4. EM (Algorithm 6, eqs. 4.27-4.30, :mod:`.vfem`), with the spatio-temporal coherence
   filter (:mod:`.vfcoherence`): a point counts for a field only within a run of
   ``coherence_run`` consecutive points of its demonstration and with another such
   point within ``coherence_radius``.
5. Candidate feature frames (Ch. 4.2.7, :mod:`.vfframes`): sphere centres and cylinder
   axes, with the centre's mean offset in the ee frame (for the pour: the bottle tip).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..skill.fields import Field
from .params import SEED, Flag, Interval, OneOf, hyperparameter
from .vfcoherence import coherent
from .vfem import FieldEM
from .vffields import (
    ESTIMATORS,
    FieldAngles,
    cylinder_field,
    displacements,
    general_field,
    held_out_angles,
    sphere_field,
    translation_field,
    unit_vectors,
)
from .vfframes import candidate_frames
from .vfmixture import mixture_fit, mixture_log_likelihood, point_log_ratios
from .vfransac import (
    SAMPLE_SIZE,
    Candidate,
    Ransac,
    best_score,
    chance,
    ransac_iterations,
    sequential_ransac,
)
from .vfselect import ModelSelection

__all__ = [
    "DEFAULT_FIELDS", "ESTIMATORS", "FIELD_TYPES", "SAMPLE_SIZE", "SELECTIONS", "THESIS_FIELDS",
    "VectorFieldLearner", "cylinder_field", "general_field", "held_out_angles", "mixture_fit",
    "mixture_log_likelihood", "point_log_ratios", "ransac_iterations", "sphere_field",
    "translation_field", "unit_vectors",
]

FIELD_TYPES = ("translation", "cylinder", "sphere", "point", "general")  # every kind the learner fits
DEFAULT_FIELDS = ("translation", "cylinder", "sphere", "general")  # what it fits unless told
THESIS_FIELDS = ("translation", "cylinder", "sphere")  # the thesis' basic fields (Ch. 4.2.2)
SELECTIONS = ("likelihood", "inliers")
Array = NDArray[np.float64]


@dataclass
class VectorFieldLearner:
    """Fit basic vector fields to demonstrations by RANSAC and EM (Algorithm 4).

    Parameters
    ----------
    n_fields : int
        n_R, fields extracted sequentially by RANSAC (thesis 2).
    em_iterations : int
        EM iterations (thesis 5).
    angle_sphere, angle_translation, angle_cylinder : float
        Inlier thresholds in degrees per field type (thesis 15 sphere, 25 translation,
        20 cylinder).
    models : tuple of str
        Field types to try.
    p_success, outlier_ratio : float
        p and e of eq. 4.23.
    min_inliers : int
        Fields with fewer points are pruned.
    min_weight : float
        Fields with a smaller mixing proportion are pruned.
    coherence : bool
        Apply the spatio-temporal coherence filter in EM.
    coherence_run : int
        Minimum run of consecutive points of one demonstration in a field.
    coherence_radius : float
        A field's point needs another of its points within this distance (m).
    min_radius, max_radius : float
        Sphere and cylinder radii (m) allowed for inliers (very large spheres look
        like any motion).
    max_cylinder_radius : float
        The largest cylinder radius instead (m): a door's hinge or a crank's axis lies
        further from the hand than a held tool's tip a sphere is about.
    refine_steps : int
        Least-squares refinements of each RANSAC winner.
    chance_weight : float
        Weight of the chance-inlier correction when comparing field types by inliers.
    selection : {"likelihood", "inliers"}
        How field types compete in each round of sequential RANSAC. ``likelihood``: by
        the BIC of a mixture of the field's direction density and uniform directions
        (:func:`~.vfmixture.mixture_log_likelihood`): a field that predicts a direction gains more
        per point it explains than one that only predicts a plane, so a cylinder beats
        the sphere that fits wherever it does, and the general field's
        cross-validated likelihood competes with the shapes'. ``inliers``: the
        thesis' MSAC inlier score with the chance correction (no general field).
    demo_tolerance : float
        A cylinder beats a sphere only where it explains their points better in all but
        this share of the demonstrations (:meth:`.vfselect.ModelSelection.nested_winner`).
    general_bandwidth : float
        Kernel width (m) of the general field.
    general_parameters : float
        Free parameters per kernel centre of the general field in the BIC (the shapes
        have 2-4 in all): the general field pays for the space it covers (one centre
        per cell of half its bandwidth), so it is chosen only where the shapes cannot
        explain the motion.
    pivot_spread : float
        A rotational field whose centre (or axis point) stays within this RMS distance
        (m) of one point of the hand over its inliers gets a point of the hand as its
        ``pivot`` (the demonstrations turned about it: a bottle's opening): the one that
        moves least over the field's steps (:func:`.vfframes.turning_point`).
    random_state : int or None
        Seed of RANSAC (flag ``--seed``).

    Attributes
    ----------
    points_, vectors_ : ndarray, (n, 3)
    quaternions_ : ndarray, (n, 4)
    demo_index_ : ndarray, (n,)
    ransac_fields_ : list of Field
    ransac_inliers_ : list of ndarray of bool, (n,)
    fields_ : list of Field
        After EM, with weight (pi), sigma and inliers filled in.
    responsibilities_ : ndarray, (n, K)
        EM membership of each point in each field (rows sum to 1).
    assignment_ : ndarray, (n,)
        Field index of each point, -1 for the background/outliers.
    candidate_frames_ : list of dict
    timings_ : dict
    """

    n_fields: int = hyperparameter(2, "RANSAC fields n_R", valid=Interval(1, 10, integer=True))
    em_iterations: int = hyperparameter(5, "EM iterations", valid=Interval(1, 100, integer=True))
    angle_sphere: float = hyperparameter(15.0, "degrees", valid=Interval(0, 90, open="low"))
    angle_translation: float = hyperparameter(25.0, "degrees", valid=Interval(0, 90, open="low"))
    angle_cylinder: float = hyperparameter(20.0, "degrees", valid=Interval(0, 90, open="low"))
    angle_point: float = hyperparameter(25.0, "degrees (a reach's goal; the translation's by default)",
                                        valid=Interval(0, 90, open="low"))
    models: tuple[str, ...] = hyperparameter(
        DEFAULT_FIELDS, "the field kinds to fit, comma-separated, of " + ",".join(FIELD_TYPES)
        + " (default " + ",".join(DEFAULT_FIELDS) + "; the thesis' are translation,cylinder,sphere; "
        "add point where reaches from scattered starts end at one goal, docs/learning.md)",
        flag="--vf-models", metavar="KINDS", valid=OneOf(FIELD_TYPES, subset=True))
    p_success: float = hyperparameter(0.99, valid=Interval(0.5, 1, open="high"))
    outlier_ratio: float = hyperparameter(0.7, valid=Interval(0, 0.99))
    min_inliers: int = hyperparameter(10, valid=Interval(3, 100_000, integer=True))
    min_weight: float = hyperparameter(0.05, valid=Interval(0, 1))
    coherence: bool = hyperparameter(True, valid=Flag())
    coherence_run: int = hyperparameter(
        3, "consecutive points a field must explain for them to count (a motion shorter than "
           "this many times --vf-spacing, a button let out again, forms no field)",
        valid=Interval(1, 1000, integer=True))
    coherence_radius: float = hyperparameter(0.05, valid=Interval(0, 1))
    min_radius: float = hyperparameter(0.02, valid=Interval(0, 1))
    max_radius: float = hyperparameter(0.3, "largest sphere radius (m)", valid=Interval(0, 5, open="low"))
    # a door's handle turns 0.3-0.5 m from its hinge (a cabinet's 0.32 m): at the
    # spheres' 0.3 m its arc was no candidate, and one translation field stood for it
    max_cylinder_radius: float = hyperparameter(
        0.6, "largest cylinder radius (m): a door's or a crank's axis from the hand",
        valid=Interval(0, 5, open="low"))
    refine_steps: int = hyperparameter(2, valid=Interval(0, 20, integer=True))
    chance_weight: float = hyperparameter(
        0.5, "weight of the chance-inlier correction when comparing field types", valid=Interval(0, 10))
    selection: str = hyperparameter(
        "likelihood", "how field types compete: likelihood (BIC of each field's direction "
        "density, with a general non-parametric field) or inliers (the thesis' MSAC score) "
        "(default %(default)s)", choices=SELECTIONS, valid=OneOf(SELECTIONS))
    demo_tolerance: float = hyperparameter(
        0.1, "share of demonstrations a cylinder may explain worse than a sphere and still "
        "be chosen over it (default %(default)s)", valid=Interval(0, 1))
    general_bandwidth: float = hyperparameter(0.02, "general field kernel width (m)",
                                              valid=Interval(0.001, 1))
    general_parameters: float = hyperparameter(
        1.0, "free parameters per kernel centre of the general field in the BIC "
        "(default %(default)s)", valid=Interval(0, 100))
    pivot_spread: float = hyperparameter(0.02, valid=Interval(0, 1))
    random_state: int | None = hyperparameter(
        0, "random seed (default %(default)s)", flag="--seed", metavar="SEED", valid=SEED)


    # --- the pipeline's parts, from the hyperparameters ---------------------------------

    def _thresholds(self) -> dict[str, float]:
        """The inlier threshold (rad) of each field shape."""
        degrees = {"sphere": self.angle_sphere, "translation": self.angle_translation,
                   "cylinder": self.angle_cylinder, "point": self.angle_point}
        return {kind: math.radians(d) for kind, d in degrees.items()}

    def chance(self, kind: str) -> float:
        """Expected MSAC score of one uniformly random direction for a field type
        (:func:`.vfransac.chance`)."""
        return chance(kind, self._thresholds()[kind])

    # --- fit --------------------------------------------------------------------------

    def fit(self, points: list[ArrayLike], quaternions: list[ArrayLike] | None = None,
            progress: Callable[[str], None] | None = None) -> VectorFieldLearner:
        """Fit on demonstrations.

        Parameters
        ----------
        points : list of array-like, each (n_i, 3)
            Subsampled positions (object frame) of the frame the fields describe.
        quaternions : list of array-like, each (n_i, 4), optional
            Orientations at those samples (kept for the neighbour orientation
            constraint and the candidate frames' ee offsets).
        progress : callable(str), optional
            Called with the stage's name as each stage ends (``ransac``, ``em``).
        """
        rng = np.random.default_rng(self.random_state)
        t0 = time.perf_counter()
        data = displacements(points, quaternions)
        self.points_, self.vectors_, self.quaternions_, self.demo_index_, self.sample_index_ = data
        angles = FieldAngles(data, self.min_radius, self.max_radius, self.max_cylinder_radius)
        self._sequential_ransac(rng, angles)
        if progress is not None:
            progress("ransac")
        t1 = time.perf_counter()
        fields, self.responsibilities_, self.assignment_ = self._em(angles)
        if progress is not None:
            progress("em")
        demo, sample = self.demo_index_, self.sample_index_
        steps = np.flatnonzero((demo[1:] == demo[:-1]) & (sample[1:] == sample[:-1] + 1))
        self.candidate_frames_, self.fields_ = candidate_frames(
            fields, self.assignment_, self.points_, self.quaternions_, self.pivot_spread, steps)
        self.timings_ = {"ransac": t1 - t0, "em": time.perf_counter() - t1}
        return self

    def _sequential_ransac(self, rng: np.random.Generator, angles: FieldAngles) -> None:
        """Algorithm 5, each round's field chosen by :attr:`selection`; then, by
        ``likelihood``, the general field may take the place of the last fields."""
        p, v, demo = self.points_, self.vectors_, self.demo_index_
        select = ModelSelection(angles, self.coherence_run, self.demo_tolerance, self.general_bandwidth,
                                self.general_parameters, self.min_inliers)
        self.selection_ = select.rounds  # each round's shapes and their evidence

        def by_likelihood(scored: list[Candidate], idx: NDArray[np.int64]) -> int:
            return select.tournament([f for f, _, _ in scored], [m for _, m, _ in scored],
                                     p[idx], v[idx], demo[idx])

        choose = by_likelihood if self.selection == "likelihood" else best_score
        ransac = Ransac(self._thresholds(), self.p_success, self.outlier_ratio, self.refine_steps,
                        self.chance_weight, angles)
        self.ransac_fields_, self.ransac_inliers_ = sequential_ransac(
            p, v, rng, ransac, self.models, self.n_fields, self.min_inliers, choose)
        if self.selection == "likelihood" and "general" in self.models:
            self.ransac_fields_, self.ransac_inliers_, self.model_scores_ = select.with_general(
                p, v, demo, self.ransac_fields_, self.ransac_inliers_)

    def _em(self, angles: FieldAngles) -> tuple[list[Field], Array, NDArray[np.int64]]:
        """Algorithm 6 from the RANSAC fields: the fields, responsibilities and each
        point's field (:meth:`.vfem.FieldEM.fit`)."""
        keep = (partial(coherent, demo=self.demo_index_, sample=self.sample_index_, points=self.points_,
                        run=self.coherence_run, radius=self.coherence_radius)
                if self.coherence else None)
        em = FieldEM(self.em_iterations, self.min_inliers, self.min_weight, angles, self.general_bandwidth,
                     keep)
        return em.fit(self.ransac_fields_, self.ransac_inliers_, self.points_, self.vectors_)
