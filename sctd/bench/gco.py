"""Our alpha-beta swap against GCO's (the C++ reference, ``pip install gco-wrapper``).

The instances are Potts energies shaped like the segmentation
:class:`~sctd.learn.LinearIMLearner` solves (Ch. 4.1.4), alternately of two families:

- :func:`segmentation_instance`: the learner's own energy on generated demonstrations
  (:mod:`sctd_sim.demogen`, pour and drawer in turn, 10 demonstrations, 5 % outliers;
  ``sctd bench learn`` takes the two from ``bench_learn`` in ``sctd/app/defaults.yaml``),
  preprocessed as ``learn_linear`` does: the 41 ``ee`` labels' costs (eq. 4.14) as
  unary, the temporal chains plus spatial k-NN edges of
  :func:`~sctd.learn.neighbour_graph` with weights ``exp(-tf-norm)``, lambda 0.005
  (pour about 580 displacements and 3100 edges, drawer about 270 and 1650);
- :func:`chain_instance`: 600 displacements in 10 chains built the same way from
  synthetic motions noisy enough that the per-node argmin spreads over 27-37 of the 41 labels.

Both minimisers start from the per-node argmin of the unary costs and run to
convergence; both energies are computed by :func:`sctd.learn.energy` in floating
point. GCO works in integers: the costs are scaled so that the largest node term is
2**20 and rounded (a relative error of about 1e-6 of it, far below the 0.5 % target).
Its time is reported twice: everything ``gco.cut_general_graph`` does (build the
graph, set the initial labels one ctypes call per node, swap), as a caller pays it,
and the swap alone.

GCO is optional: :func:`run_gco_bench` returns ``{"available": False, "reason": ...}``
when ``import gco`` fails.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sctd import se3
from sctd_sim import demogen

from ..app.defaults import defaults
from ..learn import (
    LinearIMLearner,
    Preprocessing,
    alpha_beta_swap,
    energy,
    im_costs,
    label_set,
    neighbour_graph,
)
from ..learn.preprocess import preprocess
from .demos import demo_kind, demos_of

Problem = tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64], float]
GCO_INSTALL = "pip install gco-wrapper; it is in the dev extra"
_GCO_TERM_RANGE = 2**20  # the largest scaled node term; GCO's capacities are int32


def segmentation_instance(seed: int, task: str, n_demos: int = 10,
                          outliers: float = 0.05, noise: float = 0.001,
                          learner: LinearIMLearner | None = None) -> Problem:
    """The Potts problem ``(unary (n, 41), edges (m, 2), weights (m,), lambda)`` that
    the linear-IM learner's segmentation solves on generated demonstrations of ``task``
    (``ee`` the only frame)."""
    lr = LinearIMLearner() if learner is None else learner
    ds = demogen.generate(demo_kind(task), n_demos, noise=noise, outliers=outliers, seed=seed)
    prep = Preprocessing()
    prepared = preprocess(demos_of(ds), prep, prep.spacing,
                          lr.alpha, translation_only=False)
    labels = label_set(["ee"])
    costs, starts = [], []
    for p in prepared:
        T = se3.transform_from_pose(p.poses)
        d6 = se3.displacement_from_transforms(T[:-1], T[1:])
        costs.append(im_costs(d6[None], labels, ["ee"], lr.alpha, lr.beta))
        starts.append(p.poses[:-1])
    demo_index = np.concatenate([np.full(len(c), k) for k, c in enumerate(costs)])
    edges, weights = neighbour_graph(np.concatenate(starts), demo_index, lr.radius, lr.max_n,
                                     lr.alpha)
    return np.concatenate(costs), edges, weights, float(lr.smoothness)


def chain_instance(seed: int, n_chains: int = 10, length: int = 60, n_phases: int = 4,
                   noise: float = 1.0, spacing: float = 0.02, smoothness: float = 0.005,
                   learner: LinearIMLearner | None = None) -> Problem:
    """A harder segmentation-shaped Potts problem: ``n_chains`` demonstrations of
    ``length`` displacements each, the same ``n_phases`` phases in every one (phase k
    moves along random axes of a random one of the 41 selections; the boundaries
    jitter between chains), each displacement ``spacing`` long (tf-norm) plus Gaussian
    noise of ``noise x spacing`` on all six axes, so the per-node argmin scatters over
    many labels. Unary, edges and weights as the learner builds them
    (:func:`~sctd.learn.im_costs`, :func:`~sctd.learn.neighbour_graph`)."""
    lr = LinearIMLearner(smoothness=smoothness) if learner is None else learner
    rng = np.random.default_rng(seed)
    labels = label_set(["ee"])
    axis_scale = np.array([1.0, 1.0, 1.0, 1 / lr.alpha, 1 / lr.alpha, 1 / lr.alpha])
    templates = []
    for lab in rng.choice(len(labels), n_phases):
        d = np.zeros(6)
        d[list(labels[lab].axes)] = rng.normal(size=len(labels[lab].axes))
        templates.append(d / np.linalg.norm(d) * spacing * axis_scale)
    costs, starts = [], []
    for _ in range(n_chains):
        cuts = np.sort(rng.integers(length // (2 * n_phases), length, n_phases - 1))
        phase = np.searchsorted(cuts, np.arange(length), side="right")
        d6 = np.array(templates)[phase] + rng.normal(scale=noise * spacing / np.sqrt(6),
                                                     size=(length, 6)) * axis_scale
        costs.append(im_costs(d6[None], labels, ["ee"], lr.alpha, lr.beta))
        path = np.cumsum(np.vstack([rng.normal(scale=0.01, size=6), d6]), axis=0)[:-1]
        starts.append(np.hstack([path[:, :3], se3.quaternion_from_rotvec(path[:, 3:])]))
    demo_index = np.repeat(np.arange(n_chains), length)
    edges, weights = neighbour_graph(np.concatenate(starts), demo_index, lr.radius, lr.max_n,
                                     lr.alpha)
    return np.concatenate(costs), edges, weights, float(lr.smoothness)


def gco_swap(gco: Any, unary, edges, weights, smoothness: float, labels
             ) -> tuple[NDArray[np.int64], float]:
    """GCO's alpha-beta swap to convergence from ``labels`` on the integer-scaled
    problem (``gco`` the imported module), as ``gco.cut_general_graph`` does it; also
    the seconds spent in the swap itself (without building GCO's graph)."""
    U = np.asarray(unary, dtype=float)
    U = U - U.min(axis=1, keepdims=True)  # a constant per node: same minimisers
    E = np.sort(np.asarray(edges, dtype=np.int64), axis=1)  # GCO wants s1 < s2
    wl = float(smoothness) * np.asarray(weights, dtype=float)
    degree = np.bincount(E.reshape(-1), weights=np.repeat(wl, 2), minlength=len(U))
    scale = _GCO_TERM_RANGE / max(float((U.max(axis=1) + degree).max()), 1e-300)
    # The wrapper hands the raw buffers to C without checking their layout.
    g = gco.GCO()
    g.create_general_graph(len(U), U.shape[1], False)
    try:
        g.set_data_cost(np.ascontiguousarray(np.round(U * scale), dtype=np.int32))
        g.set_all_neighbors(E[:, 0], E[:, 1], np.ascontiguousarray(np.round(wl * scale),
                                                                   dtype=np.int32))
        g.set_smooth_cost(np.ascontiguousarray(1 - np.eye(U.shape[1]), dtype=np.int32))
        for i, label in enumerate(np.asarray(labels, dtype=int)):
            g.init_label_at_site(i, label)
        t = time.perf_counter()
        g.swap(-1)
        t_swap = time.perf_counter() - t
        f = np.asarray(g.get_labels(), dtype=np.int64)
    finally:
        g.destroy_graph()
    return f, t_swap


def _import_gco() -> Any:
    """The ``gco`` module. (Importing it sets ``numpy.int``, ``numpy.float`` and
    ``numpy.bool`` to the builtins when numpy lacks them, for its own old code.)"""
    import gco

    return gco


def instances(n_instances: int, seed: int = 0, tasks: Sequence[str] | None = None
              ) -> Iterator[tuple[str, int, Problem]]:
    """``n_instances`` problems ``(family, seed, (U, E, w, lambda))``: alternately the
    learner's own (:func:`segmentation_instance`, on the generated ``tasks`` in turn:
    default ``bench_learn``'s tilt then pull, the pour then the drawer) and the harder
    :func:`chain_instance`."""
    if tasks is None:
        tasks = (defaults().bench_learn.tilt, defaults().bench_learn.pull)
    for k in range(n_instances):
        s = seed + k // 2
        if k % 2 == 0:
            task = tasks[(k // 2) % len(tasks)]
            yield task, s, segmentation_instance(s, task)
        else:
            yield "chains", s, chain_instance(s)


def run_gco_bench(n_instances: int = 20, seed: int = 0, tasks: Sequence[str] | None = None
                  ) -> dict[str, Any]:
    """Our swap and GCO's on ``n_instances`` segmentation-shaped instances
    (:func:`instances` of ``tasks``). Ratios are ours / GCO's."""
    try:
        gco = _import_gco()
    except (ImportError, OSError) as e:  # absent, or its compiled library will not load
        return {"available": False, "reason": f"{type(e).__name__}: {e}", "install": GCO_INSTALL}
    rows = []
    for task, s, (U, E, w, lam) in instances(n_instances, seed, tasks):
        f0 = np.argmin(U, axis=1)
        t = time.perf_counter()
        f_ours = alpha_beta_swap(U, E, w, lam)
        t_ours = time.perf_counter() - t
        t = time.perf_counter()
        f_gco, t_core = gco_swap(gco, U, E, w, lam, f0)
        t_gco = time.perf_counter() - t
        e0, e_ours, e_gco = (energy(U, E, w, lam, f) for f in (f0, f_ours, f_gco))
        rows.append({"seed": s, "task": task, "nodes": len(U), "labels": U.shape[1],
                     "edges": len(E), "initial": e0, "ours": e_ours, "gco": e_gco,
                     "energy_ratio": e_ours / e_gco, "ours_s": t_ours, "gco_s": t_gco,
                     "gco_swap_s": t_core, "time_ratio": t_ours / t_gco,
                     "time_ratio_swap": t_ours / t_core})
    return {"available": True, "instances": rows,
            "energy_ratio_max": max(r["energy_ratio"] for r in rows),
            "time_ratio_median": float(np.median([r["time_ratio"] for r in rows])),
            "time_ratio_swap_median": float(np.median([r["time_ratio_swap"] for r in rows])),
            "ours_s_median": float(np.median([r["ours_s"] for r in rows])),
            "gco_s_median": float(np.median([r["gco_s"] for r in rows])),
            "gco_swap_s_median": float(np.median([r["gco_swap_s"] for r in rows]))}


def format_gco_bench(r: dict[str, Any]) -> list[str]:
    """Report lines of :func:`run_gco_bench` with its targets (energy <= GCO's
    x 1.005 on every instance, time <= 10 x GCO's), then one line per instance."""
    if not r["available"]:
        return [f"[--- ] alpha-beta swap vs GCO: GCO not installed ({r['reason']}; {r['install']})"]
    rows = r["instances"]
    ok_e, ok_t = r["energy_ratio_max"] <= 1.005, r["time_ratio_median"] <= 10
    lines = [
        f"[{'ok ' if ok_e else 'MISS'}] alpha-beta swap vs GCO swap on {len(rows)} segmentation "
        f"instances: energy ours / GCO max {r['energy_ratio_max']:.5f} target <= 1.005",
        f"[{'ok ' if ok_t else 'MISS'}] alpha-beta swap vs GCO swap: time ours / GCO median "
        f"{r['time_ratio_median']:.1f}x ({r['ours_s_median'] * 1000:.1f} ms vs "
        f"{r['gco_s_median'] * 1000:.1f} ms) target <= 10x; against GCO's swap alone, "
        f"without building its graph, {r['time_ratio_swap_median']:.1f}x "
        f"({r['gco_swap_s_median'] * 1000:.1f} ms)",
    ]
    lines += [f"      seed {x['seed']:<3} {x['task']:<6} n={x['nodes']:<4} L={x['labels']:<3} "
              f"m={x['edges']:<5} E0={x['initial']:.4f} ours={x['ours']:.5f} "
              f"gco={x['gco']:.5f} ratio={x['energy_ratio']:.5f} "
              f"({x['ours_s'] * 1000:.1f} ms vs {x['gco_s'] * 1000:.1f} ms, swap alone "
              f"{x['gco_swap_s'] * 1000:.1f} ms)" for x in rows]
    return lines
