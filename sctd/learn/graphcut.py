"""Potts-model energy minimisation by graph cuts (Ch. 4.1.4, Appendix A.3).

The energy of a labelling ``f`` (eqs. 4.13-4.16) is

    E(f) = sum_i unary[i, f_i] + smoothness * sum_e weights[e] * [f_u != f_v]

over edges ``e = (u, v)``. :func:`alpha_beta_swap` (Boykov, Veksler and Zabih 2001,
Algorithm 8 of the thesis) and :func:`alpha_expansion` reach a local minimum with
respect to swap and expansion moves; each move is one s-t minimum cut on PyMaxflow,
with the move's graph built by vectorised numpy (no Python loop over edges).

Convention for the binary moves: a node in the source segment (segment 0) keeps its
"0" choice, one in the sink segment takes the "1" choice. A node's terminal capacities
are therefore ``source_cap = cost(1)`` and ``sink_cap = cost(0)``: cutting the edge
to the terminal on the other side pays the cost of the side it ends on.
"""

from __future__ import annotations

import maxflow
import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]


def _check(unary: ArrayLike, edges: ArrayLike, weights: ArrayLike,
           labels: ArrayLike | None) -> tuple[Array, IntArray, Array, IntArray]:
    U = np.asarray(unary, dtype=float)
    if U.ndim != 2 or U.shape[0] == 0 or U.shape[1] == 0:
        raise ValueError(f"unary must be (n, L) with n, L >= 1, got shape {U.shape}")
    if not np.all(np.isfinite(U)):
        raise ValueError("unary costs must be finite")
    E = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    w = np.asarray(weights, dtype=float).reshape(-1)
    if len(w) != len(E):
        raise ValueError(f"{len(E)} edges but {len(w)} weights")
    if len(E) and (E.min() < 0 or E.max() >= U.shape[0]):
        raise ValueError("edge endpoints must index rows of unary")
    if np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError("edge weights must be finite and >= 0")
    keep = E[:, 0] != E[:, 1]
    E, w = E[keep], w[keep]
    f = np.argmin(U, axis=1) if labels is None else np.asarray(labels, dtype=np.int64).copy()
    if f.shape != (U.shape[0],) or f.min() < 0 or f.max() >= U.shape[1]:
        raise ValueError("labels must be (n,) ints in [0, L)")
    return U, E, w, f.astype(np.int64)


def energy(unary: ArrayLike, edges: ArrayLike, weights: ArrayLike, smoothness: float,
           labels: ArrayLike) -> float:
    """Potts energy E(f) of eqs. 4.13-4.16.

    Parameters
    ----------
    unary : array-like, shape (n, L)
        Data cost of each label at each node (eq. 4.14).
    edges : array-like, shape (m, 2)
        Neighbour pairs (node indices).
    weights : array-like, shape (m,)
        Edge weights ``w_pq`` (eq. 4.16), >= 0.
    smoothness : float
        lambda of eq. 4.16.
    labels : array-like, shape (n,)

    Returns
    -------
    float
    """
    U = np.asarray(unary, dtype=float)
    E = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    w = np.asarray(weights, dtype=float).reshape(-1)
    f = np.asarray(labels, dtype=np.int64)
    data = float(U[np.arange(len(f)), f].sum())
    if len(E) == 0:
        return data
    return data + float(smoothness) * float(np.sum(w * (f[E[:, 0]] != f[E[:, 1]])))


def _cut(cost0: Array, cost1: Array, pu: IntArray, pv: IntArray, cap_uv: Array,
         cap_vu: Array) -> NDArray[np.bool_]:
    """Minimum cut of a binary problem; True where the node takes its "1" choice.

    ``cap_uv`` is paid when u keeps 0 and v takes 1, ``cap_vu`` the other way round.
    """
    n = len(cost0)
    g = maxflow.Graph[float](n, max(1, len(pu)))
    nodes = g.add_nodes(n)
    # Shift both terminal costs so the smaller is zero: same cut, no negative capacity.
    m = np.minimum(cost0, cost1)
    g.add_grid_tedges(nodes, cost1 - m, cost0 - m)
    if len(pu):
        g.add_edges(pu.astype(np.int32), pv.astype(np.int32), cap_uv, cap_vu)
    g.maxflow()
    return g.get_grid_segments(nodes).astype(bool)


def alpha_beta_swap(unary: ArrayLike, edges: ArrayLike, weights: ArrayLike, smoothness: float,
                    labels: ArrayLike | None = None, max_cycles: int = 20) -> IntArray:
    """Minimise the Potts energy by alpha-beta swap moves (Appendix A.3, Algorithm 8).

    For every pair of labels (alpha, beta) the nodes labelled alpha or beta are
    relabelled optimally among {alpha, beta} by one minimum cut whose terminal links
    are Table A.1's ``t^alpha_p = D_p(alpha) + sum_{q not in P_ab} V(alpha, f_q)`` and
    whose neighbour links are ``V(alpha, beta) = smoothness * w_pq``. Cycles over all
    pairs repeat until no move lowers the energy. Each accepted move never raises the
    energy.

    Parameters
    ----------
    unary : array-like, shape (n, L)
    edges : array-like, shape (m, 2) of int
    weights : array-like, shape (m,)
    smoothness : float
        lambda (eq. 4.16), >= 0.
    labels : array-like, shape (n,), optional
        Initial labelling; default the per-node argmin of ``unary``.
    max_cycles : int
        Upper bound on full cycles over the label pairs.

    Returns
    -------
    ndarray, shape (n,) of int
        The labelling.
    """
    U, E, w, f = _check(unary, edges, weights, labels)
    lam = float(smoothness)
    n, L = U.shape
    wl = lam * w
    eu, ev = E[:, 0], E[:, 1]
    best = energy(U, E, w, lam, f)
    for _ in range(max_cycles):
        improved = False
        present = np.unique(f)
        # Only pairs with at least one label in use can change anything.
        for a in range(L):
            for b in range(a + 1, L):
                if a not in present and b not in present:
                    continue
                in_ab = (f == a) | (f == b)
                idx = np.flatnonzero(in_ab)
                if len(idx) == 0:
                    continue
                local = np.full(n, -1, dtype=np.int64)
                local[idx] = np.arange(len(idx))
                cost_a = U[idx, a].copy()
                cost_b = U[idx, b].copy()
                # Edges with exactly one end in P_ab: Potts penalty to the fixed neighbour.
                iu, iv = in_ab[eu], in_ab[ev]
                for inside, node, other in ((iu & ~iv, eu, ev), (iv & ~iu, ev, eu)):
                    if not np.any(inside):
                        continue
                    p = local[node[inside]]
                    fq = f[other[inside]]
                    np.add.at(cost_a, p, wl[inside] * (fq != a))
                    np.add.at(cost_b, p, wl[inside] * (fq != b))
                both = iu & iv
                pu, pv = local[eu[both]], local[ev[both]]
                take_b = _cut(cost_a, cost_b, pu, pv, wl[both], wl[both])
                f_new = f.copy()
                f_new[idx] = np.where(take_b, b, a)
                e_new = energy(U, E, w, lam, f_new)
                if e_new < best - 1e-12 * max(1.0, abs(best)):
                    f, best, improved = f_new, e_new, True
                    present = np.unique(f)
        if not improved:
            break
    return f


def alpha_expansion(unary: ArrayLike, edges: ArrayLike, weights: ArrayLike, smoothness: float,
                    labels: ArrayLike | None = None, max_cycles: int = 20) -> IntArray:
    """Minimise the Potts energy by alpha-expansion moves (Boykov et al. 2001).

    For every label alpha each node either keeps its label or takes alpha, decided by
    one minimum cut; the Potts model is a metric, so every move is submodular and
    exactly solvable. Same signature and energy as :func:`alpha_beta_swap`.

    Returns
    -------
    ndarray, shape (n,) of int
    """
    U, E, w, f = _check(unary, edges, weights, labels)
    lam = float(smoothness)
    n, L = U.shape
    wl = lam * w
    eu, ev = E[:, 0], E[:, 1]
    best = energy(U, E, w, lam, f)
    for _ in range(max_cycles):
        improved = False
        for a in range(L):
            cost0 = U[np.arange(n), f].copy()  # keep f_p
            cost1 = U[:, a].copy()  # take alpha
            fu, fv = f[eu], f[ev]
            # Pairwise table A=E(0,0), B=E(0,1), C=E(1,0), D=E(1,1)=0 decomposed as
            # A + (C-A) x_u + (D-C) x_v + (B+C-A-D) (1-x_u) x_v.
            A = wl * (fu != fv)
            B = wl * (fu != a)
            C = wl * (a != fv)
            cu = C - A  # the constant A does not change the cut
            np.add.at(cost1, eu, np.maximum(cu, 0.0))
            np.add.at(cost0, eu, np.maximum(-cu, 0.0))
            # -C x_v == C (1 - x_v) - C: pay C when v keeps its label.
            np.add.at(cost0, ev, C)
            cap = B + C - A  # >= 0: the Potts model is a metric
            take = _cut(cost0, cost1, eu, ev, np.maximum(cap, 0.0), np.zeros_like(cap))
            f_new = np.where(take, a, f)
            e_new = energy(U, E, w, lam, f_new)
            if e_new < best - 1e-12 * max(1.0, abs(best)):
                f, best, improved = f_new, e_new, True
        if not improved:
            break
    return f
