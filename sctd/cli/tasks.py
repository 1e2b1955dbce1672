"""``sctd tasks``: the tasks ``--task NAME`` finds (the shipped task files, then those
other packages register), and ``sctd tasks show NAME|FILE``: one task's scene and how it
is judged, checked as every command that takes ``--task`` checks it (``--yaml``: its file
as :func:`sctd.task.writer.dump_task` writes it)."""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from ..app.errors import EXIT_FAILED, EXIT_OK, fail
from ..app.options import TASK_HELP
from ..task import Task, TaskError, dump_task, find_task, known_tasks, load_task
from ..task.judge import thresholds
from ..task.kinds import StepKind
from ..task.model import AllOf, Body, Compare, Predicate


def add_tasks_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION")
    show = sub.add_parser("show", help="one task: its scene, task object and outcome, validated",
                          description="one task: its scene, task object and outcome, validated")
    show.add_argument("task", metavar="NAME|FILE", help=TASK_HELP)
    fmt = show.add_mutually_exclusive_group()
    fmt.add_argument("--json", action="store_true", help="machine-readable output")
    fmt.add_argument("--yaml", action="store_true",
                     help="print the task's file as sctd writes it (sctd.task.writer.dump_task: "
                          "every value read back exactly, defaults left out); no reach check")
    show.add_argument("--urdf", metavar="FILE", default=None,
                      help="check the task's reach with this arm (as sctd sim --urdf; default: the "
                           "shipped arm)")
    show.add_argument("--ee-frame", metavar="NAME", default=None, help="the arm's hand frame (as sctd sim)")
    show.add_argument("--reach-trials", type=int, default=REACH_TRIALS, metavar="N",
                      help="also the seeded starts of evaluation trials 0..N-1 (default %(default)s)")
    show.add_argument("--no-reach", dest="reach", action="store_false",
                      help="do not check that the arm reaches the task's start")
    p.add_argument("--json", action="store_true", help="one JSON list on stdout")


REACH_TRIALS = 10  # the seeded trial starts sctd tasks show checks by default


def reach(task: Task, args: argparse.Namespace) -> dict[str, Any]:
    """Whether the arm (``--urdf``/``--ee-frame``, default the shipped one) reaches the
    task's start and the seeded starts of trials 0..``--reach-trials``-1 (each drawn
    again, as sctd sim does, while it cannot), and whether the hand can take what the
    task has it take (:func:`sctd_sim.handreach.hand_problems`): ``{"arm", "checked",
    "start", "hand", "trials"}`` with ``start`` None when reached, else why, ``hand`` the
    problems; ValueError for a bad arm."""
    try:
        from sctd_sim.handreach import hand_problems
        from sctd_sim.options import arm_from_args
        from sctd_sim.scenes import make_scene
        from sctd_sim.simulation import start_posture, trial_scene
    except ImportError as e:  # no Pinocchio: the sim extra
        return {"arm": None, "checked": False, "why": f"not checked ({e.name} is not installed: "
                                                      "pip install 'sctd[sim]')"}
    arm = arm_from_args(args)
    out: dict[str, Any] = {"arm": f"{arm.urdf_path.name} (frame {arm.ee_frame!r})", "checked": True,
                           "start": None, "trials": []}
    try:
        start_posture(arm, make_scene(task).start_pose())
    except RuntimeError as e:
        out["start"] = str(e)
        return out
    out["hand"] = hand_problems(task, arm)
    for seed in range(max(0, args.reach_trials)):
        try:
            trial_scene(task, seed, arm)
        except RuntimeError as e:
            out["trials"].append({"seed": seed, "why": str(e)})
    return out


def summary(task: Task) -> dict[str, Any]:
    """What ``sctd tasks show`` prints, as plain data."""
    sc = task.scene
    held = sc.held
    return {
        "name": task.name, "title": task.title, "description": task.description, "source": task.source,
        "object": task.object, "file": task.file,
        "bodies": {n: {"position": b.T_world[:3, 3].round(4).tolist(),
                       "container": b.container is not None} for n, b in sc.bodies.items()},
        "held": None if held is None else {
            "name": held.name, "mass": held.mass, "frames": sorted(held.frames),
            "contents": None if held.contents is None else {
                "mass": held.contents.mass, "outlet": held.contents.outlet, "into": held.contents.into}},
        "joints": {n: {"type": j.kind, "handle": j.handle, "travel": j.travel, "unit": j.unit}
                   for n, j in sc.joints.items()},
        "surfaces": {n: _surface(b) for n, b in sc.bodies.items() if b.surface is not None},
        "heads": {n: {"behind": h.behind, "radius": h.radius, "stiffness": h.stiffness, "damping": h.damping}
                  for n, h in sc.heads.items()},
        "zones": {n: {"frame": z.frame, "around": z.around, "position": z.position.tolist(),
                      "within": z.within.tolist(), "axis": z.axis.tolist() if z.tilt is not None else None,
                      "tilt": z.tilt} for n, z in sc.zones.items()},
        "frames": sc.frames(),
        "thresholds": thresholds(task.outcome.done),
        "done": _flag_terms(task.outcome.done),
        "done_reason": task.outcome.done_reason,
        "fails": [f.reason for f in task.outcome.fail],
        "progress": str(task.outcome.progress),
        "time_limit": task.outcome.time_limit,
        "facets": {n: {k: f.to_yaml() for k, f in b.facets.items()}
                   for n, b in sc.bodies.items() if b.facets},
        "sections": {k: {n: e.to_yaml() for n, e in entries.items()} for k, entries in sc.sections.items()
                     if k not in _SHOWN_SECTIONS},
        "intent": [{"name": s.name, "kind": _step_kind(s.action)} for s in task.intent],
    }


def _step_kind(action: StepKind) -> str:
    """An intent step's kind, as its file's key names it."""
    return action.key


_SHOWN_FACETS = ("container", "surface", "button")
"""Facets ``sctd tasks show`` prints lines of its own for; other kinds' print their fields."""
_SHOWN_SECTIONS = ("joints", "heads", "zones")


def _fields(d: dict[str, Any]) -> str:
    """A kind's task-file fields on one line: ``mass 0.25, radius 0.035, ...``."""
    def text(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:g}"
        if isinstance(v, list):
            return "[" + ", ".join(text(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k}: {text(x)}" for k, x in v.items()) + "}"
        return str(v)
    return ", ".join(f"{k} {text(v)}" for k, v in d.items())


def _flag_terms(p: Predicate) -> list[str]:
    """The flags a conjunction requires (``light_switch.on is true``), as text."""
    if isinstance(p, Compare) and p.is_ is not None:
        return [f"{p.reading} is {str(p.is_).lower()}"]
    if isinstance(p, AllOf):
        return [t for term in p.terms for t in _flag_terms(term)]
    return []


def _flags(terms: list[str]) -> str:
    return ", ".join(terms) or "see the file"


def _surface(body: Body) -> dict[str, Any]:
    """A body's surface and the button in it, as ``sctd tasks show`` prints them."""
    s, b = body.surface, body.button
    assert s is not None
    return {"stiffness": s.stiffness, "damping": s.damping, "friction": s.friction, "touch": list(s.touch),
            "button": None if b is None else {"radius": b.radius, "travel": b.travel, "click": b.click,
                                              "click_force": b.click_force}}


def _rows() -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for k in known_tasks():
        try:
            t = load_task(k.path)
            rows.append({"name": k.name, "title": t.title, "object": t.object, "origin": k.origin,
                         "path": str(k.path), "source": t.source})
        except TaskError as e:  # listed with its problem: the others stay usable
            rows.append({"name": k.name, "title": None, "object": None, "origin": k.origin,
                         "path": str(k.path), "error": str(e)})
    return rows


def main_tasks(args: argparse.Namespace) -> int:
    if args.action == "show":
        try:
            task = find_task(args.task)
            if args.yaml:
                print(dump_task(task), end="")
                return EXIT_OK
            s = summary(task)
            if args.reach:
                s["reach"] = reach(task, args)
        except (TaskError, ValueError) as e:
            return fail("tasks show", str(e))
        r = s.get("reach") or {}
        if r.get("start") or r.get("trials") or r.get("hand"):
            bad = r["start"] or "; ".join([*r.get("hand", []),
                                           *(f"trial {t['seed']}: {t['why']}" for t in r["trials"])])
            return fail("tasks show", f"task {task.name}: {bad}")
        if args.json:
            print(json.dumps(s, indent=2))
        else:
            _print_show(s, args)
        return EXIT_OK
    try:
        rows = _rows()
    except TaskError as e:  # a registered task whose entry point is broken
        return fail("tasks", str(e), EXIT_FAILED)
    if args.json:
        print(json.dumps(rows, indent=2))
        return EXIT_OK
    width = max((len(r["name"]) for r in rows), default=4)
    for r in rows:
        if "error" in r:
            print(f"{r['name']:<{width}}  INVALID  {r['error']}")
            continue
        print(f"{r['name']:<{width}}  {r['title']:<24}  object {r['object']:<14}  {r['origin']:<8}  "
              f"{r['path']}")
    return EXIT_FAILED if any("error" in r for r in rows) else EXIT_OK


def _print_show(s: dict[str, Any], args: argparse.Namespace) -> None:
    """``sctd tasks show``'s text: the :func:`summary` ``s``, and its reach."""
    print(f"{s['name']}: {s['title']} ({s['file']})")
    if s["description"]:
        print(f"  {s['description']}")
    if s["source"]:
        print(f"  source: {s['source']}")
    print(f"  task object: {s['object']}; frames: {', '.join(s['frames'])}")
    if s["held"]:
        h = s["held"]
        contents = f", contents into {h['contents']['into']}" if h["contents"] else ""
        print(f"  held: {h['name']} ({h['mass']} kg{contents})")
    for n, j in s["joints"].items():
        travel = f"{j['travel']:g} {j['unit']}"
        if j["unit"] == "rad":
            travel += f" ({math.degrees(j['travel']):g} deg)"
        print(f"  joint {n}: {j['type']}, handle {j['handle']}, travel {travel}")
    for n, f in s["surfaces"].items():
        print(f"  surface {n}: {f['stiffness']:g} N/m, friction {f['friction']:g}, touched by "
              f"{', '.join(f['touch'])}")
        if f["button"]:
            b = f["button"]
            print(f"  button {n}: radius {b['radius'] * 1000:g} mm, travel {b['travel'] * 1000:g} mm, "
                  f"switches at {b['click'] * 1000:g} mm ({b['click_force']:g} N)")
    for n, h in s["heads"].items():
        print(f"  head {n}: a sphere of {h['radius']:g} m behind {h['behind']}, contact "
              f"{h['stiffness']:g} N/m, {h['damping']:g} N s/m")
    for n, z in s["zones"].items():
        turned = f", z within {math.degrees(z['tilt']):.0f} deg of {_vec(z['axis'])}" if z["tilt"] else ""
        print(f"  zone {n}: {z['frame']} within {_vec(z['within'])} m of {_vec(z['position'])} in "
              f"{z['around']}{turned}")
    for n, facets in s["facets"].items():  # (the registered kinds the lines above do not show)
        for k, f in facets.items():
            if k not in _SHOWN_FACETS:
                print(f"  {k} {n}: {_fields(f)}")
    for k, entries in s["sections"].items():
        for n, e in entries.items():
            print(f"  {k} {n}: {_fields(e)}")
    targets = ", ".join(f"{k} >= {v:g}" for k, v in s["thresholds"].items()) or _flags(s["done"])
    print(f"  done ({s['done_reason']}) at {targets}; progress {s['progress']}; "
          f"fails: {', '.join(s['fails']) or 'none'}; time limit {s['time_limit']:g} s")
    steps = ", ".join(f"{st['name']} ({st['kind']})" for st in s["intent"])
    print(f"  intent: {steps}")
    r = s.get("reach") or {}
    if r.get("checked"):
        print(f"  reach: {r['arm']} reaches the start and the starts of trials 0-{args.reach_trials - 1}"
              if args.reach_trials > 0 else f"  reach: {r['arm']} reaches the start")
    elif r:
        print(f"  reach: {r['why']}")


def _vec(v: list[float]) -> str:
    return "[" + ", ".join(f"{x:g}" for x in v) + "]"
