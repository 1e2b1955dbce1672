"""Report figures like the thesis' (Figs. 4.3, 4.4, 4.7-4.11).

matplotlib's object API (:class:`~matplotlib.figure.Figure`, no pyplot): figures are
drawn off screen whatever the session's backend, and no global state is touched.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from ... import se3
from ...learn import IMLabel, LinearResult, VectorFieldResult
from ...learn.linear import AXIS_NAMES
from ...skill.fields import CylinderField, SphereField, TranslationField

_COLOURS = [matplotlib.colormaps["tab10"](k) for k in range(10)]


def _save(fig: Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def linear_figures(result: LinearResult, out: Path) -> list[Path]:
    """``im_costs.png`` (Fig. 4.3) and ``segments.png`` (Fig. 4.4) in ``out``."""
    return [_im_costs_figure(result, out / "im_costs.png"),
            _segments_figure(result, out / "segments.png")]


def _im_costs_figure(result: LinearResult, path: Path) -> Path:
    """Fig. 4.3: cost of the 1-DoF IMs over the displacements of the first demo, per frame."""
    L = result.learner
    frames = L.frame_names_
    fig = Figure(figsize=(8, 2.6 * len(frames)))
    axes = fig.subplots(len(frames), 1, squeeze=False)
    cost = L.costs_[0]
    index = {lab: j for j, lab in enumerate(L.labels_)}
    for ax, frame in zip(axes[:, 0], frames, strict=True):
        for a in range(6):
            lab = IMLabel(frame if a >= 3 else "ee", (a,))
            ax.plot(cost[:, index[lab]], label=AXIS_NAMES[a], color=_COLOURS[a])
        s = L.state_labels_[0]
        for k in range(len(L.states_)):
            idx = np.flatnonzero(s == k)
            if len(idx):
                ax.axvspan(idx[0] - 0.5, idx[-1] + 0.5, color=_COLOURS[k], alpha=0.08)
        ax.set_title(f"1-DoF IM cost seen from '{frame}' ({result.prepared[0].name}); "
                     "shading = learned state")
        ax.set_xlabel("displacement")
        ax.set_ylabel("cost (eq. 4.14)")
        ax.legend(ncol=6, fontsize=7)
    return _save(fig, path)


def _segments_figure(result: LinearResult, path: Path) -> Path:
    """Fig. 4.4: segmented trajectories with the separating hyperplane(s)."""
    L = result.learner
    fig = Figure(figsize=(11, 5))
    axes = fig.subplots(1, 2)
    for (i, j), ax in zip(((0, 2), (0, 1)), axes, strict=True):
        for prep, s in zip(result.prepared, L.state_labels_, strict=True):
            T = se3.transform_from_pose(prep.poses)
            for h_frame in {h.frame for h in L.transitions_} or {"ee"}:
                p = L.frame_positions(T[:-1], h_frame)
                ax.scatter(p[:, i], p[:, j], c=[_COLOURS[k % 10] for k in s], s=6)
                break
        for h in L.transitions_:
            n, o = h.normal, h.offset
            lim = ax.get_xlim()
            x = np.linspace(float(lim[0]), float(lim[1]), 400)
            if abs(n[j]) > 1e-6:
                # Trace of the plane at the data's mean along the hidden axis.
                k3 = 3 - i - j
                allp = np.concatenate([L.frame_positions(se3.transform_from_pose(p.poses), h.frame)
                                       for p in result.prepared])
                y = -(n[i] * x + n[k3] * allp[:, k3].mean() + o) / n[j]
                pad = 0.05
                inside = (y >= allp[:, j].min() - pad) & (y <= allp[:, j].max() + pad)
                ax.plot(x[inside], y[inside], "k--", lw=1,
                        label=f"s{h.source} -> s{h.target} plane ({h.frame})")

        ax.set_xlabel("xyz"[i] + " (m, object frame)")
        ax.set_ylabel("xyz"[j] + " (m)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=7)
    names = ", ".join(f"s{k}: {st.label.name}" for k, st in enumerate(L.states_))
    fig.suptitle(f"Segmented demonstrations (colour = state; {names})", fontsize=9)
    return _save(fig, path)


def vf_figures(result: VectorFieldResult, out: Path) -> list[Path]:
    """``fields.png`` (Figs. 4.7-4.9) and, with a candidate frame,
    ``candidate_frame.png`` (Figs. 4.10-4.11) in ``out``."""
    paths = [_fields_figure(result, out / "fields.png")]
    if result.learner.candidate_frames_:
        paths.append(_candidate_frame_figure(result, out / "candidate_frame.png"))
    return paths


def _fields_figure(result: VectorFieldResult, path: Path) -> Path:
    """Figs. 4.7-4.9: the fields with their points (colour = EM assignment, grey = outlier)."""
    V = result.learner
    p, v, a = V.points_, V.vectors_, V.assignment_
    fig = Figure(figsize=(11, 5))
    axes = fig.subplots(1, 2)
    for (i, j), ax in zip(((0, 2), (0, 1)), axes, strict=True):
        col = [(0.7, 0.7, 0.7) if k < 0 else _COLOURS[k % 10] for k in a]
        ax.quiver(p[:, i], p[:, j], v[:, i], v[:, j], color=col, scale=40, width=0.003)
        for m, f in enumerate(V.fields_):
            label = f"{m}: {f.type} ({f.inliers} pts, w={f.weight:.2f})"
            if isinstance(f, SphereField):
                ax.plot(f.centre[i], f.centre[j], "x", color=_COLOURS[m], ms=10, mew=2, label=label)
            elif isinstance(f, CylinderField):
                q = f.point + np.outer([-0.1, 0.1], f.axis)
                ax.plot(q[:, i], q[:, j], "-", color=_COLOURS[m], lw=2, label=label)
            elif isinstance(f, TranslationField):
                c = p[a == m].mean(axis=0) if np.any(a == m) else p.mean(axis=0)
                ax.annotate("", xy=(c[i] + 0.08 * f.direction[i], c[j] + 0.08 * f.direction[j]),
                            xytext=(c[i], c[j]),
                            arrowprops={"arrowstyle": "->", "color": _COLOURS[m], "lw": 2.5})
                ax.plot([], [], "-", color=_COLOURS[m], lw=2.5, label=label)
        ax.set_xlabel("xyz"[i] + " (m, object frame)")
        ax.set_ylabel("xyz"[j] + " (m)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=7)
    fig.suptitle("Vector fields after RANSAC + EM (colour = field, grey = outlier)", fontsize=9)
    return _save(fig, path)


def _candidate_frame_figure(result: VectorFieldResult, path: Path) -> Path:
    """Figs. 4.10-4.11: the candidate frame against the ee trajectory (vertical plane)."""
    V = result.learner
    fig = Figure(figsize=(6, 5))
    ax = fig.subplots()
    for prep in result.prepared:
        ax.plot(prep.poses[:, 0], prep.poses[:, 2], "-", color="0.6", lw=0.8)
    for c in V.candidate_frames_:
        ax.plot(c["position"][0], c["position"][2], "*", ms=14, label=f"{c['name']} centre")
        if "ee_offset" in c:
            R = se3.matrix_from_quaternion(V.quaternions_)
            tip = V.points_ + R @ np.asarray(c["ee_offset"])
            ax.plot(tip[:, 0], tip[:, 2], ".", ms=3, label=f"{c['name']} as ee offset "
                    f"{np.round(c['ee_offset'], 3).tolist()}")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7)
    ax.set_title("ee trajectories (grey) and candidate feature frame", fontsize=9)
    return _save(fig, path)
