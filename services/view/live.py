"""The live view: the arm, the task's scene and the active skill as they are now.

:class:`LiveView` draws a :class:`Snapshot` of what the robot's keys said last (the
service, :mod:`.service`, takes them from Zenoh with decimation and calls :meth:`draw`
at about 30 Hz):

- the arm's links (:mod:`.arm`) at the measured joint positions, when the robot
  publishes them (``state.q``); the measured hand as a frame, the target as a smaller,
  orange one;
- the task's bodies (:mod:`.task_scene`) at the poses the robot publishes, a joint's
  moving part at the position the scene reports (``<joint>.position``), what the hand
  holds in the hand;
- the active skill (fetched whole, ``skill/bundle``, whenever the daemon's skill id
  changes) at its object's pose: the active state's elements redrawn with the hand
  where it is (what each axis does *here*, the constraints at the hand's frames), a
  state picker that follows the daemon's state unless a state is picked;
- for the person in the chair, a panel readable at arm's length: the mode, what each
  axis does now, what holds the hand (a constraint it presses against), why the
  runtime holds (its ``status.mode`` and stuck report) and, with a skill set, which
  task's skill is engaged and what the runtime believes the person is going for
  (``status.goals``);
- plots of the last :data:`WINDOW` s: the input of the device that owns the motion, the
  hand's speed and the state, and the constraints' activity (``status.constraints``:
  the share of the person's commands each constraint of the active state changed).
"""

from __future__ import annotations

import html
import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sctd import se3
from sctd.runtime.goals import TELEOP
from sctd.skill import Skill
from sctd.task import Task

from .arm import ArmGeometry
from .draw import SkillView, lights
from .skill_scene import constraint_labels, holding, skill_scene, state_scene, workspace
from .task_scene import default_poses, part_pose, task_parts

WINDOW = 10.0  # s of history in the plots
REDRAW = 0.2  # s between redraws of the active state at the hand (the arrows follow it)
PLOT_EVERY = 0.2  # s between updates of the plots
CONSTRAINT_SERIES = 4  # constraints plotted (the shipped skills have at most 2 a state)
HELD = 0.5  # share of the window's commands a constraint changed for "held by" to name it
HOLDS = {"waiting": "waiting for the robot's state and the object's pose",
         "hold": "holding: the robot's state or the object's pose is stale",
         "fault": "holding: the robot's state jumped; waiting to start again from where it is",
         "stopped": "stopped: no input (or the deadman is released)"}


@dataclass
class Snapshot:
    """What the robot's keys said last (plain data from their messages)."""

    t: float = 0.0  # when it was taken (monotonic s)
    pose: list | None = None  # the measured ee in the world [7]
    q: list | None = None
    target: dict | None = None  # the target message: pose, state, skill
    objects: dict[str, list] = field(default_factory=dict)  # name -> pose [7]
    status: dict | None = None
    scene: dict | None = None
    inputs: dict[str, tuple] = field(default_factory=dict)  # device -> (u, stamp)


def _wxyz(pose) -> tuple[float, float, float, float]:
    return float(pose[6]), float(pose[3]), float(pose[4]), float(pose[5])


class LiveView:
    """Draws snapshots on ``server`` (a ``viser.ViserServer``).

    Parameters
    ----------
    server : viser.ViserServer
    arm : ArmGeometry or None
        The arm's links (None: the hand and target alone).
    task : Task or None
        The task whose scene to draw (None: none).
    """

    def __init__(self, server: Any, arm: ArmGeometry | None = None, task: Task | None = None):
        self.server, self.arm, self.task = server, arm, task
        self.skill: Skill | None = None
        self.skill_view: SkillView | None = None
        self.handles: dict[str, Any] = {}
        self._redrawn = 0.0
        self.redraws = 0  # of the active state at the hand
        self.drawn_at = 0.0  # a log's time last drawn (replay)
        self.replay_slider: Any = None
        self._redrawn_state = ""
        self._plotted = 0.0
        self._history: deque[tuple[float, ...]] = deque()
        self._legend_for: tuple[str, str] = ("", "")  # (skill id, state) the legend says
        self._last_pose: tuple[float, np.ndarray] | None = None
        lights(server)
        sc = server.scene
        sc.add_grid("/floor", width=2.0, height=2.0, cell_size=0.1, section_size=0.5)
        self.handles["/hand"] = sc.add_frame("/hand", axes_length=0.06, axes_radius=0.004, visible=False)
        self.handles["/target"] = sc.add_frame("/target", axes_length=0.04, axes_radius=0.002,
                                               origin_radius=0.008, origin_color=(255, 140, 0),
                                               visible=False)
        for k, link in enumerate(arm.links if arm is not None else []):
            self.handles[f"/arm/{k}"] = sc.add_mesh_simple(
                f"/arm/{link.name}", link.vertices.astype(np.float32), link.faces.astype(np.uint32),
                color=link.rgb, visible=False, cast_shadow=False, receive_shadow=False)
        look_at = np.array([0.3, 0.0, 0.4])  # between the arm's base and its reach
        if task is not None and task.object in task.scene.bodies:
            look_at = (task.scene.bodies[task.object].T_world[:3, 3] + np.array([0.0, 0.0, 0.35])) / 2
        server.initial_camera.look_at = tuple(look_at)
        server.initial_camera.position = tuple(look_at + np.array([0.5, -1.3, 0.7]))
        self.parts = task_parts(task) if task is not None else []
        for part in self.parts:
            self.handles[part.name] = sc.add_mesh_simple(
                f"/task/{part.name}", part.vertices.astype(np.float32), part.faces.astype(np.uint32),
                color=part.rgb, opacity=part.opacity if part.opacity < 1.0 else None, visible=False,
                cast_shadow=False, receive_shadow=False)
        self._panel()

    # -- the skill ---------------------------------------------------------------------
    def set_skill(self, skill: Skill) -> None:
        """Draw ``skill`` (replacing the one drawn)."""
        if self.skill_view is not None:
            self.skill_view.close()
        self.skill, self.ws = skill, workspace(skill)
        self.skill_view = SkillView(self.server, skill_scene(skill), task=None, live=True)
        self.skill_view.root.visible = False  # until its object's pose is known

    # -- drawing -----------------------------------------------------------------------
    def draw(self, snap: Snapshot) -> None:
        """Everything from ``snap`` (on the caller's thread; one batch of messages)."""
        with self.server.atomic():
            self._draw_robot(snap)
            self._draw_task(snap)
            self._draw_skill(snap)
        self._record(snap)
        self._describe(snap)

    def _draw_robot(self, snap: Snapshot) -> None:
        if self.arm is not None and snap.q is not None and len(snap.q) == self.arm.nq:
            for k, T in enumerate(self.arm.poses(np.asarray(snap.q, dtype=float))):
                self._put(self.handles[f"/arm/{k}"], se3.pose_from_transform(T))
        if snap.pose is not None:
            self._put(self.handles["/hand"], snap.pose)
        if snap.target is not None and snap.target.get("pose") is not None:
            self._put(self.handles["/target"], snap.target["pose"])

    def _draw_task(self, snap: Snapshot) -> None:
        if self.task is None:
            return
        T_world = default_poses(self.task) | {n: se3.transform_from_pose(p) for n, p in snap.objects.items()}
        T_ee = se3.transform_from_pose(snap.pose) if snap.pose is not None else None
        readings = (snap.scene or {}).get("readings") or {}
        for part in self.parts:
            T = part_pose(part, self.task, T_world, T_ee, readings)
            if T is not None:
                self._put(self.handles[part.name], se3.pose_from_transform(T))

    def _draw_skill(self, snap: Snapshot) -> None:
        sv, skill = self.skill_view, self.skill
        if sv is None or skill is None:
            return
        T_obj = self._object_pose(snap)
        if T_obj is None:
            return
        sv.place(T_obj)
        sv.root.visible = True
        state = (snap.target or {}).get("state") or (snap.status or {}).get("state")
        if state in [s.name for s in skill.states]:
            sv.follow(state)
        now = time.monotonic()
        if snap.pose is not None and (now - self._redrawn > REDRAW or sv.active != self._redrawn_state):
            self._redrawn, self._redrawn_state = now, sv.active  # a new state at once
            T_obj_ee = se3.invert_transform(T_obj) @ se3.transform_from_pose(snap.pose)
            i = skill.state_index(sv.active)
            sv.redraw_state(state_scene(skill, i, T_obj_ee, self.ws))
            self.redraws += 1

    def _object_pose(self, snap: Snapshot) -> np.ndarray | None:
        assert self.skill is not None
        pose = snap.objects.get(self.skill.object)
        if pose is not None:
            return se3.transform_from_pose(pose)
        if self.task is not None and self.skill.object in self.task.scene.bodies:
            return self.task.scene.bodies[self.skill.object].T_world
        return None

    @staticmethod
    def _put(handle: Any, pose) -> None:
        handle.position = np.asarray(pose[:3], dtype=float)
        handle.wxyz = _wxyz(pose)
        handle.visible = True

    # -- the person's panel and the plots ----------------------------------------------
    def _panel(self) -> None:
        from viser import uplot

        gui = self.server.gui
        with gui.add_folder("For the person"):
            self.person = gui.add_markdown("<div style='font-size:20px'>waiting for the robot</div>")
        with gui.add_folder("Plots", expand_by_default=True):
            x = np.zeros(1)
            colours = ("#e61e1e", "#14aa14", "#1e46eb")
            self.input_plot = gui.add_uplot(
                (x, x, x, x), (uplot.Series(label="t [s]"),
                               *(uplot.Series(label=f"axis {k + 1}", stroke=c, width=2)
                                 for k, c in enumerate(colours))),
                title="input (the device that owns the motion)", aspect=2.0,
                scales={"x": uplot.Scale(time=False), "y": uplot.Scale(auto=False, range=(-1.0, 1.0))})
            self.motion_plot = gui.add_uplot(
                (x, x, x), (uplot.Series(label="t [s]"), uplot.Series(label="hand speed [m/s]", stroke="#444",
                                                                        width=2),
                            uplot.Series(label="state", stroke="#ff7f0e", width=2, scale="state")),
                title="hand speed and state", aspect=2.0, scales={"x": uplot.Scale(time=False)})
            palette = ("#9467bd", "#d4a017", "#17becf", "#8c564b")
            self.constraint_plot = gui.add_uplot(
                (x,) * (1 + CONSTRAINT_SERIES),
                (uplot.Series(label="t [s]"), *(uplot.Series(label=f"constraint {k + 1}", stroke=c, width=2)
                                                 for k, c in enumerate(palette))),
                title="constraints: share of the commands each changed", aspect=2.0,
                scales={"x": uplot.Scale(time=False), "y": uplot.Scale(auto=False, range=(0.0, 1.05))})
            self.constraint_legend = gui.add_markdown("")

    def _record(self, snap: Snapshot) -> None:
        """The plots' history: owner's input, the hand's speed, the state's index."""
        status = snap.status or {}
        owner = (status.get("input") or {}).get("owner") or ""
        newest = snap.inputs.get(owner) or next(iter(snap.inputs.values()), ((), 0.0))
        u = [*newest[0], 0.0, 0.0, 0.0][:3]
        speed = 0.0
        if self._history and snap.t < self._history[-1][0]:  # scrubbed back in a log
            self._history.clear()
            self._last_pose = None
            self._plotted = -math.inf
        if snap.pose is not None:
            p = np.asarray(snap.pose[:3], dtype=float)
            if self._last_pose is not None and snap.t > self._last_pose[0]:
                speed = float(np.linalg.norm(p - self._last_pose[1]) / (snap.t - self._last_pose[0]))
            self._last_pose = (snap.t, p)
        state = (snap.target or {}).get("state")
        index = float(self.skill.state_index(state)) if self.skill is not None and state in \
            [s.name for s in self.skill.states] else float("nan")
        shares = acting(status, self.skill)
        acts = [shares[k] if shares is not None and k < len(shares) else float("nan")
                for k in range(CONSTRAINT_SERIES)]
        self._history.append((snap.t, float(u[0]), float(u[1]), float(u[2]), speed, index, *acts))
        while self._history and self._history[0][0] < snap.t - WINDOW:
            self._history.popleft()
        if snap.t - self._plotted >= PLOT_EVERY and len(self._history) > 1:
            self._plotted = snap.t
            h = np.array(self._history)
            t = h[:, 0] - h[-1, 0]
            self.input_plot.data = (t, h[:, 1], h[:, 2], h[:, 3])
            self.motion_plot.data = (t, h[:, 4], h[:, 5])
            self.constraint_plot.data = (t, *(h[:, 6 + k] for k in range(CONSTRAINT_SERIES)))

    def _legend(self, skill: Skill, state: str, labels: list[str]) -> None:
        """Under the constraints' plot: which constraint each series is, in ``state``."""
        if self._legend_for == (skill.id, state):
            return
        self._legend_for = (skill.id, state)
        lines = [f"{k + 1}: {label}" for k, label in enumerate(labels[:CONSTRAINT_SERIES])]
        if len(labels) > CONSTRAINT_SERIES:
            lines.append(f"(constraints {CONSTRAINT_SERIES + 1}-{len(labels)} are not plotted)")
        self.constraint_legend.content = f"constraints of **{state}**: " + ("; ".join(lines) or "none")

    def _describe(self, snap: Snapshot) -> None:
        """The person's panel: mode, what each axis does now, what holds the hand, why
        the runtime holds."""
        status = snap.status or {}
        lines = []
        state = (snap.target or {}).get("state") or status.get("state")
        lines.append(f"mode: <b>{state or '-'}</b>" + mode_button_words(status, state))
        sv, skill = self.skill_view, self.skill
        st = next((s for s in sv.scene.states if s.name == state), None) if sv is not None else None
        if skill is not None and st is not None:
            lines += [e.words(skill.object) for e in st.effects]
            T_obj = self._object_pose(snap)
            if T_obj is not None and snap.pose is not None:
                T_obj_ee = se3.invert_transform(T_obj) @ se3.transform_from_pose(snap.pose)
                i = skill.state_index(st.name)
                labels = constraint_labels(skill, i, T_obj_ee, self.ws)
                shares = acting(status, skill)
                if shares is not None and status["constraints"].get("state") == st.name:
                    # a bound that stops the push (a neighbour orientation acts on every
                    # command: it turns the hand, it holds nothing)
                    constraints = skill.states[i].active_constraints
                    held = [label for c, label, share in zip(constraints, labels, shares, strict=True)
                            if c.bounds and share >= HELD]
                else:  # the status does not say: where the hand is does
                    held = holding(skill, i, T_obj_ee, self.ws)
                if held:
                    lines.append("held by: " + "; ".join(held))
                self._legend(skill, st.name, labels)
        mode = status.get("mode")
        if mode in HOLDS:
            lines.append(f"<b>{HOLDS[mode]}</b>")
        stuck = status.get("stuck")
        if stuck:
            lines.append(f"<b>stuck in {stuck.get('state')} for {stuck.get('since', 0):.0f} s: the escape "
                         "button goes back</b>")
        region = status.get("region")
        if isinstance(region, dict) and region.get("inside") is False:
            away = float(region.get("outside_by", 0.0)) * 100
            lines.append(f"<b>out of this skill's region: {away:.0f} cm from where it was taught "
                         f"(around {region.get('frame')})</b>")
        lines += rearm_lines(status)
        lines += link_lines(status)
        lines += goal_lines(status)
        self.person.content = "<div style='font-size:20px'>" + "<br>".join(lines) + "</div>"


def mode_button_words(status: dict, state: str | None) -> str:
    """What the mode button does in ``state``, as the status says (``mode_button``: the
    state a press enters, or null where it changes nothing); nothing when the status
    speaks of another state or does not say."""
    if "mode_button" not in status or status.get("state") != state or state is None:
        return ""
    to = status["mode_button"]
    return f" (the mode button: to {to})" if to is not None else " (the mode button does nothing here)"


MAX_GOALS = 16  # a set's members drawn at most (the set file's limit)
# Why a device must send a zero before it moves the arm (status.input.rearm), in the
# person's words; docs/wire-contract.md, "Several devices".
REARM = {"stale": "its input stopped arriving for a while (the link stalled or dropped)",
         "stop": "after the stop", "ignored": "another device had the motion",
         "released": "the deadman was released with the stick pushed"}
MAX_REARM = 4  # devices named at most


def rearm_lines(status: dict) -> list[str]:
    """The panel's lines for the devices that must centre their stick before the arm
    moves again (``status.input.rearm``), the one whose input went stale first; nothing
    for a ``rearm`` that is not the contract's (it came off the wire)."""
    inp = status.get("input")
    rearm = inp.get("rearm") if isinstance(inp, dict) else None
    if not isinstance(rearm, dict):
        return []
    named = sorted(((str(d), why) for d, why in rearm.items() if why in REARM),
                   key=lambda dw: (dw[1] != "stale", dw[0]))
    return [f"<b>{html.escape(d)}: centre the stick to move again</b> ({REARM[why]})"
            for d, why in named[:MAX_REARM]]


# A link this late is told on the panel (ms, by the messages' stamps: docs/multihost.md,
# "What sctd does at each fault"): with the arm's state 50 ms late the assisted pour took
# 1.85 times as long as on a clean link, 20 ms cost it 1.12; the person's input 50 ms late
# cost 1.14 (sctd bench link).
SLOW_STATE_MS = 30.0
SLOW_INPUT_MS = 50.0


def link_lines(status: dict) -> list[str]:
    """The panel's lines for a slow link (``status.state_delay_ms``, ``input_delay_ms``):
    the arm's state arriving late (the arm then follows the stick more slowly) or the
    person's input; nothing on a quick link, or for a figure that is not a number."""
    lines = []
    for key, limit, words in (
            ("state_delay_ms", SLOW_STATE_MS, "the arm's link is slow: its state arrives {:.0f} ms late, "
                                              "so the arm follows more slowly"),
            ("input_delay_ms", SLOW_INPUT_MS, "the input's link is slow: it arrives {:.0f} ms late")):
        ms = status.get(key)
        if isinstance(ms, int | float) and not isinstance(ms, bool) and math.isfinite(ms) and ms > limit:
            lines.append(f"<b>{words.format(ms)}</b>")
    return lines


def goal_lines(status: dict) -> list[str]:
    """A skill set's lines of the person's panel (``status.goals``, docs/goals.md): which
    task's skill is engaged (or teleoperation), what the runtime believes the person is
    going for, most likely first, and a change waiting for the stick's release. Nothing
    for a single skill, or a ``goals`` that is not the contract's (it came off the wire)."""
    goals = status.get("goals")
    if not isinstance(goals, dict):
        return []
    engaged = goals.get("engaged")
    out = []
    if isinstance(engaged, str):
        out.append("engaged: <b>" + ("teleoperation" if engaged == TELEOP else html.escape(engaged)) + "</b>")
    belief = goals.get("belief")
    if isinstance(belief, dict):
        ranked = sorted(((str(k), float(v)) for k, v in belief.items()
                         if isinstance(v, int | float) and math.isfinite(v)), key=lambda kv: -kv[1])
        if ranked:
            out.append("going for: " + ", ".join(f"{html.escape(k)} {100 * v:.0f} %"
                                                 for k, v in ranked[:MAX_GOALS]))
    pending = goals.get("pending")
    if isinstance(pending, dict) and isinstance(pending.get("kind"), str):
        what = "leaving the skill" if pending["kind"] == "escape" else \
            f"choosing {html.escape(str(pending.get('member')))}"
        out.append(f"{what} once the stick is let go")
    return out


def acting(status: dict, skill: Skill | None) -> list[float] | None:
    """The share of the status window's commands each active constraint changed
    (``status.constraints``), or None when the status does not say it for a state of
    ``skill`` (no command in the window: all 0)."""
    got = status.get("constraints")
    if skill is None or not isinstance(got, dict) or got.get("state") not in [s.name for s in skill.states]:
        return None
    acted, commands = got.get("acted"), got.get("commands")
    n = len(skill.states[skill.state_index(got["state"])].active_constraints)
    if not isinstance(acted, list) or len(acted) != n or not isinstance(commands, int) or commands < 0:
        return None
    if commands == 0:
        return [0.0] * n
    return [min(1.0, max(0.0, float(a) / commands)) if isinstance(a, int) else 0.0 for a in acted]
