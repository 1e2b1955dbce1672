"""``sctd inspect SKILL --view``: the skill in 3D in the browser, before it ever runs.

The view (:mod:`sctd_services.view`) is served on 127.0.0.1 only, on ``--view-port`` or
a free port (the URL goes to stderr), until Ctrl-C, SIGTERM or ``--view-for`` seconds.
It reads no Zenoh key and publishes none: it shows a file.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from ..app.errors import EXIT_OK, fail
from ..skill import Skill


def add_view_arguments(p: argparse.ArgumentParser) -> None:
    """``--view`` and its options (on ``sctd inspect``)."""
    p.add_argument("--view", action="store_true",
                   help="show the skill in 3D in a browser, served on 127.0.0.1 (needs viser: "
                        "pip install 'sctd[view]'; make setup installs it)")
    p.add_argument("--demos", metavar="DIR",
                   help="with --view: the demonstrations (CSV, object frame) to draw, coloured by the "
                        "state the skill's FSM is in at each sample")
    p.add_argument("--view-port", type=int, default=0, metavar="PORT",
                   help="port of the --view page on 127.0.0.1 (default 0: a free one; the URL goes "
                        "to stderr)")
    p.add_argument("--view-for", type=float, default=None, metavar="S",
                   help="stop serving after S seconds (default: until Ctrl-C or SIGTERM)")


def check_view_arguments(args: argparse.Namespace) -> str | None:
    """What is wrong with the view's flags, or None."""
    if not args.view and (args.demos or args.view_port or args.view_for is not None):
        return "--demos, --view-port and --view-for need --view"
    if not 0 <= args.view_port <= 65535:
        return f"--view-port: not a TCP port: {args.view_port}"
    if args.view_for is not None and not args.view_for > 0:
        return f"--view-for: must be > 0, got {args.view_for}"
    return None


def serve_skill_view(skill: Skill, args: argparse.Namespace) -> int:
    """Serve the view of ``skill`` until stopped; exit code. (What it needs is imported
    here: ``sctd run`` and ``sctd inspect`` load neither the learners nor the simulator.)"""
    from sctd.learn.demos import DemoError, read_demos
    from sctd.task import task_for_object
    from sctd_services.view.draw import SkillView
    from sctd_services.view.skill_scene import skill_scene
    from sctd_sim.view import ViewerUnavailable, stop_server, viser_server

    try:
        demos = read_demos(args.demos) if args.demos else None
    except DemoError as e:
        return fail("inspect", f"--demos: {e}")
    scene = skill_scene(skill, demos)
    task = task_for_object(skill.object)
    try:
        server = viser_server(args.view_port)
    except ViewerUnavailable as e:
        return fail("inspect", f"--view: {e}")
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        SkillView(server, scene, task=task)
        print(f"sctd inspect: view of {skill.name} at http://127.0.0.1:{server.get_port()}",
              file=sys.stderr, flush=True)
        try:
            stop.wait(args.view_for)
        except KeyboardInterrupt:
            pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        stop_server(server)
    print("sctd inspect: view stopped", file=sys.stderr, flush=True)
    return EXIT_OK
