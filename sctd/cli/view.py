"""The view in the browser (:mod:`sctd_services.view`, ``docs/view.md``).

- ``sctd inspect SKILL --view``: the skill in 3D before it ever runs; it reads no Zenoh
  key and publishes none: it shows a file.
- ``sctd view``: live, next to a running daemon and robot; an observer of their keys.

Both serve on 127.0.0.1 only, on ``--view-port`` or a free port (the URL goes to
stderr), until Ctrl-C, SIGTERM or ``--view-for`` seconds.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time

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
    _add_serving(p)


def _add_serving(p: argparse.ArgumentParser) -> None:
    """``--view-port`` and ``--view-for``: where and how long the page is served."""
    p.add_argument("--view-port", type=int, default=0, metavar="PORT",
                   help="port of the page on 127.0.0.1 (default 0: a free one; the URL goes to stderr)")
    p.add_argument("--view-for", type=float, default=None, metavar="S",
                   help="stop serving after S seconds (default: until Ctrl-C or SIGTERM)")


def check_view_arguments(args: argparse.Namespace) -> str | None:
    """What is wrong with the view's flags, or None."""
    if not args.view and (getattr(args, "demos", None) or args.view_port or args.view_for is not None):
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


# -- sctd view: live ---------------------------------------------------------------------
SCENE_WAIT = 3.0  # s to wait for the simulator's scene message naming the task


def add_live_arguments(p: argparse.ArgumentParser) -> None:
    """``sctd view``'s flags."""
    from ..app.options import add_robot_argument
    from ..wire.session import add_zenoh_arguments

    p.description = ("The live view of a robot running sctd: the arm, the task's scene, the active skill "
                     "where the hand is, a panel for the person and plots, in a browser on 127.0.0.1. "
                     "An observer: it only subscribes, and queries the active skill.")
    add_robot_argument(p)
    p.add_argument("--task", metavar="NAME|FILE",
                   help="the task whose scene to draw (default: the one the simulator's scene key names, "
                        "if any)")
    p.add_argument("--urdf", metavar="FILE",
                   help="the arm's URDF, its <visual> primitives drawn at state.q (default: the simulated "
                        "arm's)")
    p.add_argument("--log", metavar="FILE.mcap",
                   help="show a log of sctd log --mcap instead of the live keys, with a timeline to scrub "
                        "(no Zenoh session is opened)")
    p.add_argument("--skill", metavar="SKILL",
                   help="with --log: the skill to draw (default: the one whose id the log's status names, "
                        "if sctd finds it: the learner's store, the shipped skills)")
    p.add_argument("--stats-json", action="store_true",
                   help="on exit, print what the view did as JSON on stdout: frames drawn, messages read "
                        "by key, undecodable messages, the skill ids it drew, failed fetches")
    _add_serving(p)
    add_zenoh_arguments(p)


def main_view(args: argparse.Namespace) -> int:
    """``sctd view``: serve the live view until stopped."""
    import logging

    from sctd_services.view.arm import ArmGeometry
    from sctd_services.view.live import LiveView
    from sctd_services.view.service import run_view
    from sctd_sim.view import ViewerUnavailable, stop_server, viser_server

    from ..wire import Keys
    from ..wire.session import session_from_args

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stderr)
    args.view = True
    problem = check_view_arguments(args)
    if problem is not None:
        return fail("view", problem)
    try:
        arm = ArmGeometry(args.urdf or _default_urdf())
    except (OSError, ValueError, RuntimeError) as e:
        return fail("view", f"--urdf: {e}")
    if args.log is not None:
        if args.stats_json:
            return fail("view", "--stats-json reports on the live view: not with --log")
        return _replay(args, arm)
    keys = Keys(args.robot)
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        with session_from_args(args) as session:
            task = _task(args.task, session, keys)
            if isinstance(task, str):
                return fail("view", task)
            try:
                server = viser_server(args.view_port)
            except ViewerUnavailable as e:
                return fail("view", str(e))
            try:
                print(f"sctd view: robot {args.robot} at http://127.0.0.1:{server.get_port()}",
                      file=sys.stderr, flush=True)
                if args.view_for is not None:
                    timer = threading.Timer(args.view_for, stop.set)
                    timer.daemon = True
                    timer.start()
                try:
                    report = run_view(session, keys, LiveView(server, arm, task), stop)
                except KeyboardInterrupt:
                    report = None
            finally:
                stop_server(server)
    finally:
        signal.signal(signal.SIGTERM, previous)
    _report(report, args.stats_json)
    return EXIT_OK


def _report(report: dict | None, as_json: bool) -> None:
    """The view's last words: a line for the person, and JSON when asked."""
    if report is None:
        print("sctd view: stopped", file=sys.stderr, flush=True)
        return
    read = ", ".join(f"{k} {n}" for k, n in report["read"].items()) or "nothing"
    print(f"sctd view: stopped after {report['frames']} frames; read {read}; "
          f"{report['dropped']} undecodable; skills drawn: {', '.join(report['skills']) or 'none'}",
          file=sys.stderr, flush=True)
    if as_json:
        import json

        print(json.dumps(report), flush=True)


def _default_urdf():
    from sctd_sim.robot import URDF_PATH

    return URDF_PATH


def _task(ref: str | None, session, keys):
    """The task to draw: ``--task``, else the one the scene key names (None when none
    does within :data:`SCENE_WAIT`); a sentence when ``--task`` names none."""
    from ..task import TaskError, find_task
    from ..wire import codec

    if ref is not None:
        try:
            return find_task(ref)
        except (TaskError, OSError) as e:
            return f"--task: {e}"
    import zenoh

    with session.declare_subscriber(keys.scene, zenoh.handlers.RingChannel(1)) as sub:
        end = time.monotonic() + SCENE_WAIT
        while time.monotonic() < end:
            sample = sub.try_recv()
            if sample is not None:
                name = codec.unpack_map(sample.payload.to_bytes()).get("scene")
                try:
                    return find_task(str(name))
                except (TaskError, OSError):
                    return None
            time.sleep(0.05)
    return None


def _replay(args: argparse.Namespace, arm) -> int:
    """``sctd view --log FILE``: the log on a timeline (no Zenoh)."""
    from sctd_services.view.live import LiveView
    from sctd_services.view.timeline import Timeline, run_replay
    from sctd_sim.view import ViewerUnavailable, stop_server, viser_server

    from ..skill import SkillError, load_skill
    from ..skill.catalog import find_skill
    from ..task import TaskError, find_task
    from ..wire import Keys
    from .log import LogError, read_log

    try:
        timeline = Timeline(read_log(args.log), Keys(args.robot).prefix)
    except (LogError, OSError) as e:
        return fail("view", f"--log: {e}")
    if not timeline.tracks:
        return fail("view", f"--log: {args.log}: nothing logged under {Keys(args.robot).prefix}/")
    scene = timeline.at(timeline.duration).scene or {}
    try:
        task = find_task(args.task or str(scene.get("scene"))) if args.task or scene.get("scene") else None
    except (TaskError, OSError) as e:
        if args.task:
            return fail("view", f"--task: {e}")
        task = None
    refs = [args.skill] if args.skill else timeline.skill_ids()[:1]
    skill = None
    for ref in refs:
        try:
            skill = load_skill(find_skill(ref) if args.skill else _skill_by_id(ref))
        except SkillError as e:
            if args.skill:
                return fail("view", f"--skill: {e}")
            print(f"sctd view: the log's skill {ref} is not found here: drawn without it", file=sys.stderr)
    try:
        server = viser_server(args.view_port)
    except ViewerUnavailable as e:
        return fail("view", str(e))
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        view = LiveView(server, arm, task)
        if skill is not None:
            view.set_skill(skill)
        print(f"sctd view: {args.log} ({timeline.duration:.1f} s) at http://127.0.0.1:{server.get_port()}",
              file=sys.stderr, flush=True)
        if args.view_for is not None:
            timer = threading.Timer(args.view_for, stop.set)
            timer.daemon = True
            timer.start()
        try:
            run_replay(view, timeline, stop)
        except KeyboardInterrupt:
            pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        stop_server(server)
    print("sctd view: stopped", file=sys.stderr, flush=True)
    return EXIT_OK


def _skill_by_id(skill_id: str):
    """The skill file whose bundle has ``skill_id``: the learner's store (by id), else a
    shipped skill. Raises SkillError naming the id when none has it."""
    from ..skill import SkillError, bundle_from_file
    from ..skill.catalog import find_stored, shipped_skills

    stored = find_stored(skill_id)
    if stored is not None:
        return stored.path
    for path in shipped_skills():
        try:
            if bundle_from_file(path).id == skill_id:
                return path
        except SkillError:
            continue
    raise SkillError(skill_id, "", "no stored or shipped skill has this id")
