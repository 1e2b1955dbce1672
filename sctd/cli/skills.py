"""``sctd skills``: the skills that ``--skill NAME`` can find (the learner's store, then
the shipped ones), ``sctd skills show NAME`` (what ``sctd inspect`` prints) and ``sctd
skills swap REF`` (put a stored skill back into the running daemon: a rollback)."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from ..app.errors import EXIT_FAILED, EXIT_OK, fail
from ..app.options import SKILL_HELP, add_robot_argument
from ..skill import SkillError, bundle_from_file, load_skill, skill_summary
from ..skill.catalog import (
    StoredSkill,
    find_stored,
    shipped_folder,
    shipped_sets,
    shipped_skills,
    store_folder,
    stored_skills,
)
from ..skill.skillset import load_skill_set
from ..wire import Keys, client
from ..wire.session import add_zenoh_arguments, session_from_args
from .run import main_inspect


def add_skills_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION")
    show = sub.add_parser("show", help="what sctd inspect prints for one skill",
                          description="what sctd inspect prints for one skill")
    show.add_argument("skill", help=SKILL_HELP)
    show.add_argument("--json", action="store_true", help="machine-readable output")
    swap = sub.add_parser("swap", help="put a stored skill (NAME@ID, ID or NAME) into the running "
                                       "daemon: a rollback to an earlier one",
                          description="put a stored skill into the running daemon")
    swap.add_argument("ref", metavar="REF", help="a stored skill: NAME@ID, ID (or a prefix of 4+ "
                                                 "characters), or NAME (the newest)")
    swap.add_argument("--member", metavar="NAME", default=None,
                      help="the member of the daemon's skill set it replaces (default: the member of "
                           "the skill's own name; docs/skill-sets.md)")
    add_robot_argument(swap)
    swap.add_argument("--timeout", type=float, default=40.0,
                      help="s to wait for the daemon's reply (default %(default)s)")
    add_zenoh_arguments(swap)
    sets = sub.add_parser("sets", help="the shipped skill sets (--set NAME finds them)",
                          description="the shipped skill sets (sctd run --set NAME finds them; "
                                      "sctd inspect --set NAME checks one)")
    sets.add_argument("--json", action="store_true", help="one JSON list on stdout")
    p.add_argument("--json", action="store_true", help="one JSON list on stdout")


def _row(path: Path, source: str) -> dict[str, Any]:
    try:
        s = skill_summary(load_skill(path))
    except SkillError as e:
        return {"name": path.stem, "id": None, "object": None, "method": None, "source": source,
                "path": str(path), "error": str(e)}
    methods = sorted({m["type"] for st in s["states"] for m in st["input_mappings"]})
    return {"name": path.stem, "id": s["id"], "object": s["object"], "method": "+".join(methods),
            "source": source, "path": str(path)}


def _stored_row(s: StoredSkill) -> dict[str, Any]:
    row = _row(s.path, "store")
    rec = s.record
    ev = {task: f"{e['successes']}/{e['trials']}" for task, e in rec.get("evaluation", {}).items()}
    return {**row, "name": s.name, "ref": s.ref, "task": rec.get("task"), "created": s.created,
            "demos": len(rec.get("demos", [])), "evaluation": ev,
            "checked": bool(ev)}


def main_skills(args: argparse.Namespace) -> int:
    if args.action == "show":
        return main_inspect(args)
    if args.action == "swap":
        return main_skills_swap(args)
    if args.action == "sets":
        return main_skills_sets(args)
    rows = [_stored_row(s) for s in reversed(stored_skills())]  # newest first
    rows += [_row(p, "shipped") for p in shipped_skills()]
    if args.json:
        print(json.dumps(rows))
        return EXIT_OK
    if not rows:
        return fail("skills", f"no skills in {store_folder()} nor {shipped_folder()}", 1)
    print(f"{'name':22s} {'id':18s} {'object':15s} {'method':22s} source")
    for r in rows:
        where = r["path"]
        if r["source"] == "store":
            made = time.strftime("%Y-%m-%d %H:%M", time.localtime(r["created"]))
            checks = ", ".join(f"{t} {v}" for t, v in r["evaluation"].items()) or "NOT CHECKED"
            where = f"{made}, {r['demos']} demos, {checks}; {where}"
        print(f"{r['name']:22s} {r['id'] or '-':18s} {r['object'] or '-':15s} "
              f"{r['method'] or r.get('error', '-'):22s} {r['source']} ({where})")
    sets = [p.stem for p in shipped_sets()]
    if sets:
        print(f"skill sets (sctd skills sets): {', '.join(sets)}")
    return EXIT_OK


def _set_row(path: Path) -> dict[str, Any]:
    try:
        s = load_skill_set(path)
    except SkillError as e:
        return {"name": path.stem, "members": [], "description": "", "path": str(path), "error": str(e)}
    return {"name": s.name, "members": [m.name for m in s.members], "teleop": s.teleop.name,
            "description": s.description, "path": str(path)}


def main_skills_sets(args: argparse.Namespace) -> int:
    """``sctd skills sets``: the shipped skill sets, each read and checked."""
    rows = [_set_row(p) for p in shipped_sets()]
    if args.json:
        print(json.dumps(rows))
        return EXIT_OK
    if not rows:
        return fail("skills", f"no skill sets in {shipped_folder()}", 1)
    print(f"{'name':16s} {'members':40s} description")
    for r in rows:
        what = r.get("error") or f"{r['description']} ({r['path']})"
        print(f"{r['name']:16s} {', '.join(r['members']) or '-':40s} {what}")
    return EXIT_OK


def main_skills_swap(args: argparse.Namespace) -> int:
    """``sctd skills swap REF``: the stored skill's bundle to the daemon."""
    try:
        stored = find_stored(args.ref)
        if stored is None:
            known = ", ".join(s.ref for s in stored_skills()) or "none"
            return fail("skills swap", f"{args.ref}: no such skill in the store {store_folder()} "
                                       f"(stored: {known})")
        bundle = bundle_from_file(stored.path)
    except SkillError as e:
        return fail("skills swap", str(e))
    with session_from_args(args) as session:
        ok, body = client.swap(session, Keys(args.robot), bundle, args.timeout, member=args.member)
    if not ok:
        return fail("skills swap", body.get("error", str(body)), EXIT_FAILED)
    member = f", replacing its set's member {body['member']}" if body.get("member") else ""
    print(f"{stored.ref}: swapped into the daemon (state {body.get('state')}{member})")
    return EXIT_OK
