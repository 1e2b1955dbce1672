"""``sctd run``, ``sctd inspect`` and ``sctd swap``."""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import os
import signal
import sys
import threading
from contextlib import ExitStack
from typing import Any

import zenoh

from ..app.defaults import defaults
from ..app.errors import EXIT_FAILED, EXIT_OK, fail
from ..app.options import SKILL_HELP, add_arguments, add_robot_argument, check_ranges, from_namespace
from ..runtime.controller import RuntimeConfig
from ..runtime.daemon import Daemon, check_no_rate_limit, ingress_limits
from ..runtime.sets import goal_set, set_summary
from ..skill import Bundle, Skill, SkillError, bundle_from_file, load_skill, skill_from_bundle, skill_summary
from ..skill.catalog import find_skill, find_skill_set
from ..skill.skillset import load_skill_set, skill_set_of
from ..timing import threads_niced
from ..wire import Keys, client
from ..wire.ros_options import add_ros_arguments, check_ros_arguments
from ..wire.session import (
    SessionSettings,
    add_zenoh_arguments,
    close_session,
    make_config,
    session_from_args,
)
from .view import add_view_arguments, check_view_arguments, serve_skill_view

log = logging.getLogger("sctd.run")

ZERO_ALLOWED = {"deadband", "stuck_after"}  # settings for which 0 means none (the rest must be > 0)


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--skill", action="append", metavar="SKILL",
                      help=SKILL_HELP + "; given two or more times, a skill set of them (the shipped "
                           "teleoperation runs until one engages; docs/skill-sets.md)")
    what.add_argument("--set", dest="skill_set", metavar="FILE",
                      help="a skill set file, or the name of a shipped set (kitchen): teleoperation runs "
                           "until the person's motion (or button 3, choose) engages one of its skills "
                           "(docs/skill-sets.md)")
    add_arguments(p, RuntimeConfig, exclude=("stamp_check",), show_default=True)
    add_arguments(p, RuntimeConfig, only=("stamp_check",))
    grip = defaults().gripper  # the grasp button's, from sctd/app/defaults.yaml
    p.set_defaults(grasp_force=grip.force, grasp_open_hold=grip.open_hold)
    p.add_argument("--spin-us", type=float, default=100.0,
                   help="us before each deadline the tick thread wakes: it drains its inputs, then "
                        "spins to the deadline; 0: it wakes at the deadline, cheapest, with the "
                        "drain and the timer's wake-up delay as lateness (sctd bench cost prints "
                        "CPU and lateness for each) (default %(default)s)")
    p.add_argument("--rt-priority", type=int, default=10,
                   help="SCHED_FIFO priority of the tick thread, 0 for none; falls back to normal "
                        "priority when not permitted (default %(default)s)")
    p.add_argument("--io-nice", type=int, default=0,
                   help="nice value of the Zenoh session's own threads, which receive and send every "
                        "message, -20 to 19; 0 (the default) leaves them at the daemon's. Under a "
                        "flood of input the tick thread can wait for one of them that holds a receive "
                        "ring's lock; a negative nice runs it sooner then (sctd bench flood compares "
                        "two values on this machine; docs/benchmarks.md). A negative one needs the "
                        "privilege SCHED_FIFO needs; without it the threads keep the daemon's nice, "
                        "and the status' io_nice says so")
    p.add_argument("--cpu", type=int, default=None,
                   help="pin the tick thread to this CPU (best with that CPU kept free of other work, "
                        "e.g. isolcpus)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--stats-json", action="store_true", help="print final statistics as JSON on exit")
    add_ros_arguments(p, "the target as geometry_msgs/msg/PoseStamped on <namespace>/target_pose "
                         "and sensor_msgs/msg/Joy taken as input from <namespace>/joy")
    p.add_argument("--ros-joy-map", metavar="FILE", default=None,
                   help="input mapping file for the Joy axes and buttons (docs/input.md; default: "
                        "the shipped xbox map, which matches the joy package's game_controller_node)")
    add_zenoh_arguments(p)


def _joy_map(path: str | None) -> Any:
    """``(axes, buttons) -> (u [6], [mode, enable, escape], stop)`` through the mapping
    file ``path`` (default: the shipped xbox map)."""
    from sctd_services.input.mapping import joy_function

    return joy_function(path)


def _runtime_ros(args: argparse.Namespace, session: zenoh.Session, config: RuntimeConfig) -> Any:
    """The daemon's ROS side (``--ros``); None without it. Joy input is put on the
    daemon's own device key (``ros`` when it follows any device)."""
    if not args.ros:
        return None
    from ..wire import ros

    device = "ros" if config.device == "*" else config.device
    return ros.RuntimeRos(session, Keys(config.robot).input(device), _joy_map(args.ros_joy_map),
                          args.ros_namespace, args.ros_domain, args.ros_rate, config.input_timeout)


def runtime_config(args: argparse.Namespace) -> RuntimeConfig:
    """The RuntimeConfig of parsed ``sctd run`` flags.

    Raises
    ------
    ValueError
        A setting out of range, naming its flag.
    """
    config = from_namespace(RuntimeConfig, args)
    check_ranges(config, ZERO_ALLOWED)
    Keys(config.robot)  # one key chunk
    return config


def _stop_on_signals() -> threading.Event:
    """An event set by SIGINT/SIGTERM. Installed before anything is bound, so that a
    signal that comes while the daemon is still starting also ends it cleanly (exit 0,
    port freed)."""
    stop = threading.Event()

    def on_signal(signum: int, frame: Any) -> None:
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    return stop


def daemon_skills(args: argparse.Namespace) -> dict[str, Any]:
    """What the daemon runs, as :class:`~sctd.runtime.daemon.Daemon`'s keyword arguments:
    one skill (``--skill`` once), or a skill set (``--set``, or ``--skill`` two or more
    times).

    Raises
    ------
    SkillError
        A skill or set file that does not validate, naming the file and the field.
    """
    refs = args.skill or []
    if args.skill_set is None and len(refs) == 1:
        bundle = bundle_from_file(find_skill(refs[0]))
        return {"skill": skill_from_bundle(bundle), "bundle": bundle.pack()}
    spec = load_skill_set(find_skill_set(args.skill_set)) if args.skill_set is not None \
        else skill_set_of(refs)
    return {"skill": None, "goals": goal_set(spec), "set_name": spec.name,
            "set_bundles": {sid: b.pack() for sid, b in spec.bundles().items()}}


def main_run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stderr)
    try:
        what = daemon_skills(args)
        config = runtime_config(args)
        check_ros_arguments(args)
    except (SkillError, ValueError) as e:
        return fail("run", str(e))
    if not -20 <= args.io_nice <= 19:
        return fail("run", f"--io-nice: {args.io_nice}: a nice value is -20 to 19")
    n_cpus = os.cpu_count() or 1
    if args.cpu is not None and not 0 <= args.cpu < n_cpus:
        return fail("run", f"--cpu: {args.cpu}: this machine has CPUs 0-{n_cpus - 1}")
    stop = _stop_on_signals()
    try:
        conf = make_config(args.listen, args.connect, args.zenoh_config, **ingress_limits(config.robot))
    except (ValueError, zenoh.ZError) as e:
        return fail("run", f"cannot open Zenoh session: {e}")
    try:
        check_no_rate_limit(conf, config.robot)
    except ValueError as e:
        return fail("run", f"{args.zenoh_config}: {e}")
    try:
        with threads_niced(args.io_nice) as io_nice:  # the session's threads start in here
            session = zenoh.open(conf)
    except (ValueError, zenoh.ZError) as e:
        return fail("run", f"cannot open Zenoh session: {e}")
    if io_nice != args.io_nice:
        log.warning("could not run the Zenoh session's threads at nice %d (needs CAP_SYS_NICE or an "
                    "RLIMIT_NICE); they run at %d", args.io_nice, io_nice)
    with ExitStack() as stack:
        stack.callback(close_session, session)  # last: after the ROS side and the daemon
        try:
            ros = _runtime_ros(args, session, config)
        # the mapping file's InputError is a RuntimeError
        except (ImportError, ValueError, RuntimeError, OSError, zenoh.ZError) as e:
            return fail("run", f"--ros: {e}")
        if ros is not None:
            stack.enter_context(ros)
        daemon = Daemon(session=session, config=config, spin=args.spin_us * 1e-6,
                        rt_priority=args.rt_priority, cpu=args.cpu, io_nice=io_nice, stop_event=stop,
                        # wire contract v1: on the loopback defaults, bundles sent to the
                        # skill key still swap; with a config file only skill/swap does
                        swap_on_skill_key=args.zenoh_config is None, ros=ros,
                        settings=SessionSettings.from_args(args), **what)
        stats = daemon.run(args.duration)
    if args.stats_json:
        print(json.dumps(stats))
    return EXIT_OK


def add_inspect_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("skill", nargs="?", help=SKILL_HELP)
    p.add_argument("--set", dest="skill_set", metavar="NAME|FILE",
                   help="check a skill set file instead (a path, or a shipped set's name) and show "
                        "its members, start regions and belief (docs/skill-sets.md)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    add_view_arguments(p)


def main_inspect(args: argparse.Namespace) -> int:
    problem = check_view_arguments(args)
    if problem is not None:
        return fail("inspect", problem)
    if getattr(args, "skill_set", None) is not None:
        if args.skill is not None or args.view:
            return fail("inspect", "--set: a set alone (no SKILL, no --view)")
        return _inspect_set(args)
    if args.skill is None:
        return fail("inspect", "SKILL or --set: which skill (or skill set) to check")
    try:
        skill = load_skill(find_skill(args.skill))
    except SkillError as e:
        return fail("inspect", str(e))
    if args.view:
        return serve_skill_view(skill, args)
    s = skill_summary(skill)
    if args.json:
        print(json.dumps(s, indent=2))
    else:
        _print_summary(skill, s)
    return EXIT_OK


def _inspect_set(args: argparse.Namespace) -> int:
    """``sctd inspect --set``: the set file checked as ``sctd run --set`` checks it, and
    what it holds."""
    try:
        spec = load_skill_set(find_skill_set(args.skill_set))
        goals = goal_set(spec)
    except SkillError as e:
        return fail("inspect", str(e))
    s = {"source": str(spec.source), "description": spec.description, **set_summary(spec.name, goals),
         "belief": dataclasses.asdict(goals.model)}
    del s["engaged"]  # (the running daemon's: not a file's)
    s["members"] = [m | {"start": skill.start} for m, skill in
                    zip(s["members"], (g.skill for g in goals.members), strict=True)]
    if args.json:
        print(json.dumps(s, indent=2))
        return EXIT_OK
    print(f"skill set {s['name']} ({s['source']}): {s['description']}")
    b = s["belief"]
    print(f"  belief: beta {b['beta']} /m, threshold {b['threshold']}, floor {b['floor']}, escape factor "
          f"{b['escape_factor']}, rearm travel {b['rearm_travel']} m, rest {b['rest_speed']} m/s "
          f"within {b['rest_radius']} m")
    t = s["teleop"]
    print(f"  teleoperation {t['name']} (id {t['id']})")
    for m in s["members"]:
        print(f"  member {m['name']} (id {m['id']}), object {m['object']}, starts in {m['start']}: within "
              f"{m['reach']} m of {m['point']} (tolerances {m['position_tolerance']} m, "
              f"{m['angle_tolerance']} rad)")
    return EXIT_OK


def _print_summary(skill: Skill, s: dict[str, Any]) -> None:
    """The summary ``s`` of ``skill`` for a person; each input mapping says what it does."""
    print(f"skill {s['name']} (id {s['id']}), object {s['object']}: {s['description']}")
    print(f"  limits: {s['limits']['max_linear_speed']} m/s, {s['limits']['max_angular_speed']} rad/s")
    for name, f in s["frames"].items():
        print(f"  frame {name}: parent {f['parent']}, pose {f['pose']}")
    for state, st in zip(skill.states, s["states"], strict=True):
        mark = " (start)" if st["name"] == s["start"] else ""
        mark += " (end)" if st["name"] == s["end"] else ""
        frame = f" in the frame of {state.object}" if state.object and state.object != skill.object else ""
        print(f"  state {st['name']}{mark}{frame}")
        for m in state.input_mappings:
            print(f"    IM {m.type} on {m.frame}: {m.describe()}")
        for c in st["active_constraints"]:
            extra = {k: v for k, v in c.items() if k not in ("type", "frame")}
            print(f"    AC {c['type']} on {c['frame']}: {extra}")
        if st.get("gripper") is not None:
            print(f"    gripper when a transition enters it: {st['gripper']}")
    for t in s["transitions"]:
        extra = {k: v for k, v in t.items() if k not in ("from", "to", "type")}
        print(f"  {t['from']} -> {t['to']} ({t['type']}): {extra}")
    for f in s["fields"]:
        print(f"  field {f}")
    for c in s["candidate_frames"]:
        print(f"  candidate frame {c}")


def add_swap_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("skill", help="the skill to send to the running daemon; " + SKILL_HELP)
    p.add_argument("--member", metavar="NAME", default=None,
                   help="the member of the daemon's skill set the skill replaces (default: the member "
                        "of the skill's own name; docs/skill-sets.md)")
    add_robot_argument(p)
    p.add_argument("--timeout", type=float, default=10.0, help="s to wait for the daemon's reply")
    add_zenoh_arguments(p)


def main_swap(args: argparse.Namespace) -> int:
    try:
        bundle = bundle_from_file(find_skill(args.skill))
        skill_from_bundle(bundle)  # refuse locally what the daemon would refuse
        payload = bundle.pack()
        Bundle.unpack(payload)  # the size limit too
    except SkillError as e:
        return fail("swap", str(e))
    keys = Keys(args.robot)
    if args.member is not None and not client.member_name_ok(args.member):
        return fail("swap", f"--member: {args.member!r}: {client.MEMBER_NAME_RULE}")
    with session_from_args(args) as session:
        ok, body = client.swap(session, keys, bundle, args.timeout, member=args.member)
    if ok:
        print(body.get("id"))
        return EXIT_OK
    if body.get("unanswered"):
        return fail("swap", body["error"], EXIT_FAILED)
    return fail("swap", f"refused by the daemon: {body.get('error', body)}", EXIT_FAILED)
