"""``sctd``: learn Shared Control Templates from demonstrations and run them.

Every command is one entry of :data:`COMMANDS` (``sctd bench ...`` one of
:data:`BENCHES`): the module that defines its flags (``add_arguments``) and runs it
(``main``), and its one-line help. Only the module of the command being run is imported,
so ``sctd run`` starts without scikit-learn, Pinocchio or matplotlib, and ``sctd --help``
without any of them.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib.metadata import version

from ..app import logs
from ..app.defaults import DefaultsError
from ..app.errors import EXIT_FAILED, EXIT_USAGE, Parser, fail


@dataclass(frozen=True)
class Command:
    """One ``sctd`` command: ``module.add_arguments(parser)`` defines its flags,
    ``module.main(args) -> exit code`` runs it; or a group of subcommands."""

    help: str
    module: str = ""
    add_arguments: str = ""
    main: str = ""
    group: Mapping[str, Command] = field(default_factory=dict)
    metavar: str = "BENCH"  # a group's: what its subcommands are

    def attach(self, p: argparse.ArgumentParser, argv: list[str]) -> None:
        """Give ``p`` this command's flags (a group: its subcommands, the chosen one's
        flags only), importing the module of the chosen command alone."""
        if self.group:
            _subcommands(p, self.group, argv, self.metavar)
            return
        try:
            mod = importlib.import_module(self.module)
        except ModuleNotFoundError as e:
            p.exit(EXIT_USAGE, f"{p.prog}: {_missing_extra(e)}\n")
        getattr(mod, self.add_arguments)(p)
        main: Callable[[argparse.Namespace], int] = getattr(mod, self.main)
        p.set_defaults(func=main)


# The optional libraries and the extra (pyproject.toml) that installs each.
EXTRA_OF = {"sklearn": "learn", "maxflow": "learn", "matplotlib": "learn", "pinocchio": "sim",
            "can": "sim", "cantools": "sim", "viser": "view", "atheris": "dev", "sdl2": "inputs",
            "hid": "inputs", "brainflow": "inputs", "mcap": "logs", "rclpy": "ros2", "geometry_msgs": "ros2",
            "sensor_msgs": "ros2", "diagnostic_msgs": "ros2", "dask": "cluster", "distributed": "cluster",
            "franky": "franky", "franky_sim": "dev", "mujoco": "dev"}

BENCHES: dict[str, Command] = {
    "check": Command("the learner's sequential check: its operating points (exact, simulated), and "
                     "request -> swapped skill next to the daemon", "sctd.bench.check",
                     "add_check_bench_arguments", "main_check_bench"),
    "cost": Command("what the daemon and the simulator cost (CPU, lateness, latency for each spin) and "
                    "the lockstep step, against a baseline tree in the same run", "sctd.bench.cost",
                    "add_cost_bench_arguments", "main_cost_bench"),
    "view": Command("the daemon's tick with the live view and a browser attached, alternating with it "
                    "closed", "sctd.bench.view", "add_view_bench_arguments", "main_view_bench"),
    "ros": Command("a person's Joy through sctd ros to the ROS target, against a bare rclpy round trip; "
                   "the node's CPU", "sctd.bench.ros", "add_ros_bench_arguments", "main_ros_bench"),
    "latency": Command("daemon tick timing and input->target latency vs a Zenoh echo",
                       "sctd.bench.latency", "add_latency_arguments", "main_latency"),
    "robustness": Command("the daemon next to the sim under floods, bad bundles, swaps and a jumping "
                          "state", "sctd.bench.robustness", "add_robustness_arguments",
                          "main_robustness"),
    "flood": Command("the tick under a valid-input flood, the daemon's Zenoh threads at --io-nice and at "
                     "a baseline nice, interleaved", "sctd.bench.flood", "add_flood_bench_arguments",
                     "main_flood_bench"),
    "fuzz": Command("coverage-guided fuzzing of every decoder, the bundle unpacker and the skill "
                    "loader (atheris)", "sctd.bench.fuzz", "add_fuzz_arguments", "main_fuzz"),
    "hostile": Command("hostile files to the commands that read them, hostile requests and "
                       "demonstrations to the learner next to the daemon", "sctd.bench.hostile",
                       "add_hostile_arguments", "main_hostile"),
    "learn": Command("learning figures on generated demonstrations (accuracy, centre error, "
                     "directions, time, graph-cut energy)", "sctd.bench.learn",
                     "add_bench_learn_arguments", "main_bench_learn"),
    "sim": Command("simulator real-time factor, step response and tracking",
                   "sctd.bench.sim", "add_bench_sim_arguments", "main_bench_sim"),
    "input": Command("a stick moved on a virtual pad -> the daemon's target, next to a Zenoh echo; "
                     "the EMG chain's processing latency", "sctd.bench.input",
                     "add_bench_input_arguments", "main_bench_input"),
    "multihost": Command("sctd across network namespaces (router, robot, runtime, input hosts): "
                         "latency vs a Zenoh echo, reconnection after a router restart",
                         "sctd.bench.multihost", "add_bench_multihost_arguments",
                         "main_bench_multihost"),
    "link": Command("real-time trials of tasks, assisted and teleoperated, through the namespaced "
                    "cluster with delays and stalls on the input and robot links (the fault proxy)",
                    "sctd.bench.link", "add_bench_link_arguments", "main_bench_link"),
    "eval": Command("lockstep trials in this process: simulated and wall time, real-time factor, "
                    "ms per step", "sctd.bench.eval", "add_bench_eval_arguments", "main_bench_eval"),
    "vf": Command("a vector-field skill's tick cost against its number of demonstration points "
                  "(300 to 20k), next to the hand-written pour; --daemon adds the daemon's",
                  "sctd.bench.vf", "add_bench_vf_arguments", "main_bench_vf"),
    "robot": Command("sctd's path to a franky arm (target stamp -> reference handed to franky, tracking, "
                     "the driver's CPU) against a bare franky client's loop, both on franky-sim",
                     "sctd.bench.robot", "add_bench_robot_arguments", "main_bench_robot"),
    "kernels": Command("the same sctd suite trials with this CPU's BLAS kernels and with others "
                       "(OPENBLAS_CORETYPE, default Haswell): the outcomes that differ, trial for trial",
                       "sctd.bench.kernels", "add_bench_kernels_arguments", "main_bench_kernels"),
    "cluster": Command("short lockstep trials on local processes and on a loopback Dask cluster with as "
                       "many workers: the cluster's overhead per trial", "sctd.bench.cluster",
                       "add_bench_cluster_arguments", "main_bench_cluster"),
}

CLUSTER: dict[str, Command] = {
    "scheduler": Command("a Dask scheduler for lockstep trials (127.0.0.1, no dashboard; --certs: TLS)",
                         "sctd.cli.cluster", "add_scheduler_arguments", "main_scheduler"),
    "worker": Command("Dask worker processes for a scheduler (127.0.0.1, no dashboard; --certs: TLS)",
                      "sctd.cli.cluster", "add_worker_arguments", "main_worker"),
}

COMMANDS: dict[str, Command] = {
    "run": Command("run a skill (or a skill set): the fixed-rate daemon", "sctd.cli.run",
                   "add_run_arguments", "main_run"),
    "inspect": Command("validate a skill and show its structure", "sctd.cli.run",
                       "add_inspect_arguments", "main_inspect"),
    "view": Command("the live view in a browser: the arm, the task, the active skill where the hand is",
                    "sctd.cli.view", "add_live_arguments", "main_view"),
    "swap": Command("hot-swap a skill into the running daemon", "sctd.cli.run",
                    "add_swap_arguments", "main_swap"),
    "skills": Command("list the skills --skill NAME finds (stored and shipped); skills show NAME "
                      "inspects one, skills swap ID puts a stored one back into the daemon",
                      "sctd.cli.skills", "add_skills_arguments", "main_skills"),
    "tasks": Command("list the tasks --task NAME finds (shipped and registered); tasks show NAME|FILE "
                     "checks and shows one", "sctd.cli.tasks", "add_tasks_arguments", "main_tasks"),
    "demo": Command("run a skill end to end on this machine (daemon, robot, user)", "sctd.cli.demo",
                    "add_demo_arguments", "main_demo"),
    "try": Command("drive a skill yourself from a browser page (gamepad, keyboard or touch), each trial "
                   "judged and recorded", "sctd.cli.tryout", "add_try_arguments", "main_try"),
    "learn": Command("learn a skill from a folder of demonstrations", "sctd.cli.learn",
                     "add_learn_arguments", "main_learn"),
    "dtw": Command("dynamic time warping distance between two demonstrations", "sctd.cli.learn",
                   "add_dtw_arguments", "main_dtw"),
    "eval": Command("measure a skill's assistance with the simulated user (success, time, effort; "
                    "lockstep or real time)", "sctd.cli.eval", "add_eval_arguments", "main_eval"),
    "suite": Command("every task x its skills x the competent baseline in lockstep: one table and "
                     "figures", "sctd.cli.suite", "add_suite_arguments", "main_suite"),
    "study": Command("a user study: plan (counterbalanced, seeded), run --simulated, report (tables, paired "
                     "tests, figures)", "sctd.cli.study", "add_study_arguments", "main_study"),
    # the simulator and the recorder define their flags where they live, once: the same
    # as python -m sctd_sim.service / python -m sctd_services.record take
    "sim": Command("the Pinocchio simulator as a real-time Zenoh service", "sctd_sim.service",
                   "add_service_arguments", "run"),
    "robot": Command("serve a robot driver on the wire (sim, kinematic, franky, or a registered one): "
                     "state out, targets in, faults on sctd/<robot>/robot", "sctd_services.robots.service",
                     "add_arguments", "run"),
    "record": Command("record a demonstration (ee in the task object's frame) as CSV",
                      "sctd_services.record", "add_arguments", "run"),
    "ros": Command("a ROS 2 node (rclpy): a ROS 2 arm, its perception and joystick as sctd's robot, "
                   "objects and input; the target and diagnostics out", "sctd_services.ros2.node",
                   "add_arguments", "run"),
    "learner": Command("the learner service: stores demonstrations, trains on request, checks and "
                       "hot-swaps", "sctd_services.learner", "add_arguments", "run"),
    "train": Command("ask the learner to train a skill from stored demonstrations, check and swap it",
                     "sctd.cli.train", "add_train_arguments", "main_train"),
    "teach": Command("show a task on the simulated arm N times, varied as a person would, and "
                     "record the demonstrations that succeed", "sctd.cli.teach",
                     "add_teach_arguments", "main_teach"),
    "input": Command("bridge an input device (gamepad, SpaceMouse, EMG, keyboard) to "
                     "sctd/<robot>/input/<name>", "sctd_services.input", "add_arguments", "run"),
    "certs": Command("make a private CA, one key pair per role and each role's Zenoh config",
                     "sctd.cli.certs", "add_certs_arguments", "main_certs"),
    "router": Command("a Zenoh router (mutual TLS and the roles' access control with --config)",
                      "sctd.cli.router", "add_router_arguments", "main_router"),
    "echo": Command("print the samples on a key, decoded (msgpack), like ros2 topic echo",
                    "sctd.cli.echo", "add_echo_arguments", "main_echo"),
    "hz": Command("each key's sample rate and interval spread, like ros2 topic hz", "sctd.cli.echo",
                  "add_hz_arguments", "main_hz"),
    "log": Command("record the contract's keys (targets, status, input, state, objects, scene) "
                   "into an MCAP file Foxglove opens", "sctd.cli.log", "add_log_arguments", "main_log"),
    "replay": Command("publish a log's observation keys again (state, objects, scene, status; "
                      "--all: also target, input, can), never over a live daemon or robot",
                      "sctd.cli.log", "add_replay_arguments", "main_replay"),
    "cluster": Command("a Dask scheduler or workers that sctd eval --scheduler and the learner run "
                       "lockstep trials on", group=CLUSTER, metavar="ROLE"),
    "bench": Command("benchmarks that print figures", group=BENCHES),
}


def _missing_extra(e: ModuleNotFoundError) -> str:
    """``needs <module>, which is not installed: pip install 'sctd[<extra>]'`` for an
    optional library; re-raises ``e`` for any other missing module (a bug)."""
    top = (e.name or "").split(".")[0]
    if top not in EXTRA_OF:
        raise e
    return f"needs {top}, which is not installed: pip install 'sctd[{EXTRA_OF[top]}]'"


def _subcommands(parser: argparse.ArgumentParser, commands: Mapping[str, Command], argv: list[str],
                 metavar: str) -> None:
    sub = parser.add_subparsers(dest=metavar.lower(), required=True, metavar=metavar)
    chosen = argv[0] if argv else None
    for name, cmd in commands.items():
        p = sub.add_parser(name, help=cmd.help, description=cmd.help)
        if name == chosen:
            cmd.attach(p, argv[1:])


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    """The ``sctd`` parser with the flags of the command ``argv`` names."""
    parser = Parser(prog="sctd", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version", version=f"sctd {version('sctd')}")
    _subcommands(parser, COMMANDS, argv, "COMMAND")
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    try:  # a command's flags may take their defaults from sctd/app/defaults.yaml
        parser = build_parser(argv)
    except DefaultsError as e:
        return fail(" ".join(argv[:2] if argv[:1] == ["bench"] else argv[:1]), str(e))
    args = parser.parse_args(argv)
    name = " ".join(n for n in (args.command, getattr(args, "bench", None)) if n)
    rc = EXIT_FAILED
    try:
        rc = int(args.func(args) or 0)
    except ModuleNotFoundError as e:  # an optional library imported once the command runs
        rc = fail(name, _missing_extra(e))
    except DefaultsError as e:  # a benchmark's workload, read as it runs
        rc = fail(name, str(e))
    except BrokenPipeError:  # the reader went away (sctd skills | head): not our error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        rc = 0
    finally:
        logs.finish(rc == 0)
    return rc


if __name__ == "__main__":
    sys.exit(main())
