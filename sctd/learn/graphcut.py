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

from collections.abc import Callable
from dataclasses import dataclass

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


@dataclass(frozen=True)
class _Potts:
    """A validated Potts problem: unary (n, L), edges (m, 2) without self-loops, weights
    (m,), lambda, and the scaled weights ``lambda * w`` the moves' graphs use."""

    U: Array
    E: IntArray
    w: Array
    lam: float

    @property
    def wl(self) -> Array:
        return self.lam * self.w

    def energy(self, f: IntArray) -> float:
        return energy(self.U, self.E, self.w, self.lam, f)


_Move = Callable[[_Potts, IntArray, NDArray[np.bool_], tuple[int, ...]], IntArray | None]


def _descend(unary: ArrayLike, edges: ArrayLike, weights: ArrayLike, smoothness: float,
             labels: ArrayLike | None, max_cycles: int,
             moves: Callable[[int], list[tuple[int, ...]]], move: _Move) -> IntArray:
    """Shared driver of both algorithms: cycle over ``moves(L)`` (label pairs or labels),
    keep each proposal of ``move`` that lowers the energy, stop after a cycle without
    improvement. ``move`` gets the labels in use (recomputed after each accepted move)
    and returns the proposed labelling, or None when the move cannot change anything."""
    U, E, w, f = _check(unary, edges, weights, labels)
    problem = _Potts(U, E, w, float(smoothness))
    best = problem.energy(f)
    present = np.zeros(U.shape[1], dtype=bool)
    present[f] = True
    for _ in range(max_cycles):
        improved = False
        for key in moves(U.shape[1]):
            f_new = move(problem, f, present, key)
            if f_new is None:
                continue
            e_new = problem.energy(f_new)
            if e_new < best - 1e-12 * max(1.0, abs(best)):
                f, best, improved = f_new, e_new, True
                present = np.zeros(U.shape[1], dtype=bool)
                present[f] = True
        if not improved:
            break
    return f


def _label_pairs(L: int) -> list[tuple[int, ...]]:
    return [(a, b) for a in range(L) for b in range(a + 1, L)]


def _single_labels(L: int) -> list[tuple[int, ...]]:
    return [(a,) for a in range(L)]


def _swap_move(problem: _Potts, f: IntArray, present: NDArray[np.bool_],
               pair: tuple[int, ...]) -> IntArray | None:
    """Relabel the nodes labelled a or b optimally among {a, b} (Table A.1)."""
    a, b = pair
    # Only pairs with at least one label in use can change anything.
    if not (present[a] or present[b]):
        return None
    U, wl = problem.U, problem.wl
    eu, ev = problem.E[:, 0], problem.E[:, 1]
    in_ab = (f == a) | (f == b)
    idx = np.flatnonzero(in_ab)
    local = np.full(len(f), -1, dtype=np.int64)
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
    take_b = _cut(cost_a, cost_b, local[eu[both]], local[ev[both]], wl[both], wl[both])
    f_new = f.copy()
    f_new[idx] = np.where(take_b, b, a)
    return f_new


def _expansion_move(problem: _Potts, f: IntArray, present: NDArray[np.bool_],
                    label: tuple[int, ...]) -> IntArray:
    """Let every node keep its label or take alpha, by one (submodular) cut."""
    (a,) = label
    U, wl = problem.U, problem.wl
    eu, ev = problem.E[:, 0], problem.E[:, 1]
    cost0 = U[np.arange(len(f)), f].copy()  # keep f_p
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
    return np.where(take, a, f)


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
    return _descend(unary, edges, weights, smoothness, labels, max_cycles, _label_pairs,
                    _swap_move)


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
    return _descend(unary, edges, weights, smoothness, labels, max_cycles, _single_labels,
                    _expansion_move)
