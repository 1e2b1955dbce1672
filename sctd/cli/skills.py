"""``sctd skills``: the skills that ``--skill NAME`` can find, and ``sctd skills show
NAME`` (what ``sctd inspect`` prints)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from ..skill import SkillError, load_skill, skill_summary
from ..skill.catalog import shipped_folder, shipped_skills
from .errors import EXIT_OK, fail
from .options import SKILL_HELP
from .run import main_inspect


def add_skills_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION")
    show = sub.add_parser("show", help="what sctd inspect prints for one skill",
                          description="what sctd inspect prints for one skill")
    show.add_argument("skill", help=SKILL_HELP)
    show.add_argument("--json", action="store_true", help="machine-readable output")
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


def main_skills(args: argparse.Namespace) -> int:
    if args.action == "show":
        return main_inspect(args)
    rows = [_row(p, "shipped") for p in shipped_skills()]
    if args.json:
        print(json.dumps(rows))
        return EXIT_OK
    if not rows:
        return fail("skills", f"no skills in {shipped_folder()}", 1)
    print(f"{'name':14s} {'id':18s} {'object':15s} {'method':22s} source")
    for r in rows:
        print(f"{r['name']:14s} {r['id'] or '-':18s} {r['object'] or '-':15s} "
              f"{r['method'] or r.get('error', '-'):22s} {r['source']} ({r['path']})")
    return EXIT_OK



