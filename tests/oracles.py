"""Oracles: independent implementations the tests check sctd against. They answer the
same question as the code under test by another route, so a test that compares the two
fails when either is wrong; nothing in the package uses them."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, maximum_flow

from sctd.learn import energy
from sctd.task import handle_jacobian, handle_pose
from sctd.task.kinds.joint import Joint


def reference_swap(unary, edges, weights, smoothness, labels=None, scale: float = 1e6,
                   max_cycles: int = 20) -> np.ndarray:
    """An independent alpha-beta swap (BVZ01) on scipy's integer max-flow.

    Graph per move: node 0 is the alpha terminal (source), node 1 the beta terminal
    (sink), nodes 2.. the displacements labelled alpha or beta. Capacities are the
    Table A.1 weights times ``scale``, rounded. A node cut off from the source pays its
    alpha t-link and takes alpha.
    """
    U = np.asarray(unary, dtype=float)
    E = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    w = np.asarray(weights, dtype=float)
    lam = float(smoothness)
    f = np.argmin(U, axis=1) if labels is None else np.asarray(labels).copy()
    _n, L = U.shape
    cur = energy(U, E, w, lam, f)
    for _ in range(max_cycles):
        changed = False
        for a in range(L):
            for b in range(a + 1, L):
                nodes = np.flatnonzero((f == a) | (f == b))
                if len(nodes) == 0:
                    continue
                pos = {int(p): k + 2 for k, p in enumerate(nodes)}
                ta = U[nodes, a].copy()
                tb = U[nodes, b].copy()
                src, dst, cap = [], [], []
                for (u, v), we in zip(E, w, strict=True):
                    iu, iv = int(u) in pos, int(v) in pos
                    if iu and iv:
                        src += [pos[int(u)], pos[int(v)]]
                        dst += [pos[int(v)], pos[int(u)]]
                        cap += [lam * we, lam * we]
                    elif iu or iv:
                        p, q = (u, v) if iu else (v, u)
                        k = pos[int(p)] - 2
                        ta[k] += lam * we * (f[q] != a)
                        tb[k] += lam * we * (f[q] != b)
                m = len(nodes) + 2
                src += [0] * len(nodes) + list(range(2, m))
                dst += list(range(2, m)) + [1] * len(nodes)
                cap += list(ta) + list(tb)
                C = csr_matrix((np.round(np.asarray(cap) * scale).astype(np.int64),
                                (np.asarray(src), np.asarray(dst))), shape=(m, m))
                C.sum_duplicates()
                flow = maximum_flow(C, 0, 1).flow
                residual = (C - flow)
                residual.data = (residual.data > 0).astype(np.int64)
                residual.eliminate_zeros()
                reach = breadth_first_order(residual, 0, directed=True, return_predecessors=False)
                source_side = np.zeros(m, dtype=bool)
                source_side[reach] = True
                g = f.copy()
                g[nodes] = np.where(source_side[2:], b, a)
                e = energy(U, E, w, lam, g)
                if e < cur - 1e-12:
                    f, cur, changed = g, e, True
        if not changed:
            break
    return f




@dataclass
class HandleState:
    """A joint's state as :func:`reference_handle_step` steps it."""

    position: float = 0.0
    speed: float = 0.0
    attached: bool = False
    grasps: int = 0


def reference_handle_step(joint: Joint, s: HandleState, T_world_ee: np.ndarray, twist: np.ndarray,
                          T_world_handle0: np.ndarray, dt: float) -> np.ndarray:
    """A joint's handle stepped on 3-vectors, as the scene's documentation states it:
    the handle where :func:`~sctd.task.handle_pose` puts it, ``J`` its derivative, a
    spring-damper between it and the hand once grasped, the joint driven by ``J . F`` on
    the handle against its spring, damper and tanh friction, of inertia ``mass |J|^2``
    (``mass`` for a prismatic joint, whose ``J`` is the unit axis), semi-implicit Euler,
    end stops at 0 and the travel. Returns the force on the hand (3,)."""
    G = joint.grasp
    handle = handle_pose(joint, T_world_handle0, s.position)[:3, 3]
    J = handle_jacobian(joint, T_world_handle0, s.position)
    d = T_world_ee[:3, 3] - handle
    dist = float(np.linalg.norm(d))
    if not s.attached and dist <= G.radius:
        s.attached, s.grasps = True, s.grasps + 1
    elif s.attached and dist > G.release:
        s.attached = False
    f = np.zeros(3)
    if s.attached:
        f = -G.stiffness * d - G.damping * (twist[:3] - s.speed * J)
    resist = (-joint.spring * s.position - joint.damping * s.speed
              - joint.friction * math.tanh(s.speed / joint.friction_speed))
    inertia = joint.mass if joint.kind == "prismatic" else joint.mass * float(J @ J)
    s.speed += (float(-f @ J) + resist) / inertia * dt
    s.position += s.speed * dt
    if s.position <= 0.0:
        s.position, s.speed = 0.0, max(s.speed, 0.0)
    elif s.position >= joint.travel:
        s.position, s.speed = joint.travel, min(s.speed, 0.0)
    return f
