"""``sctd bench robot --driver franky``: what sctd's path to a franky arm costs, against
the bare franky client's own loop measured in the same run (the floor).

Against franky-sim (started here on a loopback address of its own), twice:

1. **floor**: a bare franky client (this module, ``--bare``, as a process of its own)
   streams a reference to franky's ``CartesianImpedanceTrackingMotion`` at 1 kHz, moving
   back and forth along x at the speed of the teleoperation skill (0.10 m/s, 0.1 m each
   way): the reference's age when ``set_reference`` returned, the hand's distance to
   the reference at each state, and the process's CPU;
2. **sctd**: ``sctd run`` on the teleoperation skill and ``sctd robot franky``; this
   process is the person, pushing +x and -x alternately (1 s each, full deflection).
   Figures from the robot service's status (``target_latency_ms``: the daemon's target
   stamp to the reference handed to franky; ``tracking_mm``) and the CPU of the robot
   service's process (from ``/proc``).

Both compensate franky-sim's joint friction (its model's values, ``--friction``), as
a lab would its arm's identified friction; the bare client runs once more without, to
show what the compensation buys. The arm's own clock decides what "1 kHz" is:
franky-sim keeps real time only where it has a core to itself; the table prints its pace
(states per second of wall time).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import resource
import socket
import sys
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import numpy as np

from sctd.app.errors import EXIT_FAILED, fail
from sctd.cli.procs import Child, free_port
from sctd.timing import Histogram, Ticker
from sctd.wire import Keys, codec
from sctd.wire.session import session as zsession
from sctd_services.robots.franky import FRANKY_SIM_FRICTION

from .cost import tree_cpu

SPEED = 0.10  # m/s, the teleoperation skill's at full input
AMPLITUDE = 0.05  # m each side of the start


def free_loopback(ports: tuple[int, ...] = (1337, 1338)) -> str:
    """A 127.x.y.z address whose ``ports`` are free: libfranka's ports are fixed, so each
    franky-sim gets an address of its own."""
    rng = random.Random(os.getpid() ^ time.monotonic_ns())
    for _ in range(200):
        host = f"127.{rng.randint(1, 254)}.{rng.randint(0, 255)}.{rng.randint(1, 254)}"
        try:
            for port in ports:
                with socket.socket() as s:
                    s.bind((host, port))
            return host
        except OSError:
            continue
    raise RuntimeError("no free loopback address for franky-sim")


def wait_listening(host: str, port: int, child: Child, seconds: float) -> bool:
    """Whether ``host:port`` accepts connections within ``seconds`` (while ``child`` runs)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end and child.running():
        with socket.socket() as s:
            s.settimeout(0.2)
            if s.connect_ex((host, port)) == 0:
                return True
        time.sleep(0.1)
    return False


# --- the floor: a bare franky client ----------------------------------------------------------

def bare_client(host: str, seconds: float, friction: bool = True) -> dict[str, Any]:
    """Stream a triangle-wave reference to franky's tracking motion at 1 kHz for
    ``seconds`` (with franky-sim's joint friction compensated, or not); the loop's
    figures."""
    import franky

    robot = franky.Robot(host, realtime_config=franky.RealtimeConfig.Ignore)
    T0 = np.asarray(robot.current_pose.end_effector_pose.matrix)
    params = None
    if friction:
        params = franky.FrictionCompensationParams(coulomb=list(FRANKY_SIM_FRICTION), viscous=[0.0] * 7,
                                                   max_torque=list(FRANKY_SIM_FRICTION))
    motion = franky.CartesianImpedanceTrackingMotion(translational_stiffness=2000.0,
                                                     rotational_stiffness=150.0, friction=params)
    motion.set_reference(franky.CartesianReference(target=franky.Affine(T0)))
    robot.move(motion, asynchronous=True)
    age, tracking = Histogram(), Histogram()
    ticker = Ticker(0.001, spin=0.0)
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    start = time.monotonic()
    states, last_t = 0, None
    while (now := ticker.wait()[0]) - start < seconds:
        t = now - start
        phase = (SPEED * t) % (4 * AMPLITUDE)  # a triangle wave: 0 -> +A -> 0 -> -A -> 0
        x = (phase if phase < AMPLITUDE else 2 * AMPLITUDE - phase if phase < 3 * AMPLITUDE
             else phase - 4 * AMPLITUDE)
        T = T0.copy()
        T[0, 3] += x
        made = time.time()
        motion.set_reference(franky.CartesianReference(target=franky.Affine(T)))
        age.add(time.time() - made)
        st = robot.state
        if st.time != last_t:
            states += 1
            last_t = st.time
            tracking.add(float(np.linalg.norm(np.asarray(st.O_T_EE.matrix)[:3, 3] - T[:3, 3])))
    wall = time.monotonic() - start
    cpu1 = resource.getrusage(resource.RUSAGE_SELF)
    robot.move(franky.TorqueStopMotion(), asynchronous=True)
    robot.join_motion(timeout=2.0)
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    return {"reference_age_ms": age.summary_ms(), "tracking_mm": tracking.summary_ms(),
            "cpu_cores": round(cpu / wall, 3), "states_per_s": round(states / wall, 1),
            "seconds": round(wall, 2)}


# --- sctd's path ------------------------------------------------------------------------------

def _push(pub: Any, seconds: float) -> None:
    """Full pushes along +x and -x, 1 s each, at 100 Hz, deadman held."""
    seq, start = 0, time.monotonic()
    while (t := time.monotonic() - start) < seconds:
        u = [1.0 if int(t) % 2 == 0 else -1.0, 0.0, 0.0]
        pub.put(codec.encode_input(seq, time.time(), u, [0, 1, 0]))
        seq += 1
        time.sleep(0.01)


def sctd_path(host: str, seconds: float, logdir: str) -> dict[str, Any]:
    """The daemon and ``sctd robot franky`` against franky-sim at ``host``, pushed."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    keys = Keys("edan")
    last: dict[str, Any] = {}
    with ExitStack() as stack:
        stack.enter_context(Child("sctd.cli.main", "run", "--skill", "teleop", "--listen", ep,
                                  log=Path(logdir) / "daemon.log"))
        robot = stack.enter_context(Child("sctd.cli.main", "robot", "franky", "--host", host,
                                          "--realtime", "ignore", "--connect", ep, "--friction",
                                          ",".join(f"{x:g}" for x in FRANKY_SIM_FRICTION),
                                          log=Path(logdir) / "robot.log"))
        s = stack.enter_context(zsession(connect=[ep]))
        sub = s.declare_subscriber(keys.robot_status,
                                   lambda x: last.update(status=codec.unpack_map(x.payload.to_bytes())))
        pub = s.declare_publisher(keys.input("bench"))
        end = time.monotonic() + 60
        while last.get("status", {}).get("readings", 0) < 500:
            if time.monotonic() > end or not robot.running():
                raise RuntimeError(f"sctd robot franky did not start; see {logdir}")
            time.sleep(0.1)
        cpu0, r0, w0 = tree_cpu(robot.p.pid)[0], last["status"]["readings"], time.monotonic()
        _push(pub, seconds)
        cpu1, r1, w1 = tree_cpu(robot.p.pid)[0], last["status"]["readings"], time.monotonic()
        st = dict(last["status"])
        sub.undeclare()
        pub.undeclare()
    return {"target_latency_ms": st["target_latency_ms"], "tracking_mm": st["tracking_mm"],
            "cpu_cores": round((cpu1 - cpu0) / (w1 - w0), 3), "states_per_s": round((r1 - r0) / (w1 - w0), 1),
            "seconds": round(w1 - w0, 2), "faults": len(st["faults"]),
            "target_rejected": st["target_rejected"]}


# --- the command --------------------------------------------------------------------------------

def add_bench_robot_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--driver", default="franky", choices=["franky"],
                   help="the driver to measure (default %(default)s: against franky-sim)")
    p.add_argument("--seconds", type=float, default=10.0, help="each phase's length (default %(default)s)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.add_argument("--logs", default=None, metavar="DIR", help="keep the processes' logs here")
    p.add_argument("--bare", metavar="HOST", help=argparse.SUPPRESS)  # the floor's own process
    p.add_argument("--bare-without-friction", action="store_true", help=argparse.SUPPRESS)


def _phase_floor(host: str, seconds: float, logdir: str, friction: bool = True) -> dict[str, Any]:
    extra = () if friction else ("--bare-without-friction",)
    with Child("sctd.bench.robot", "--bare", host, "--seconds", str(seconds), *extra) as c:
        out = c.communicate(timeout=seconds + 60)
    lines = [ln for ln in out.splitlines() if ln.startswith("{")]
    if not lines:
        raise RuntimeError("the bare franky client reported nothing")
    return json.loads(lines[-1])


def main_bench_robot(args: argparse.Namespace) -> int:
    if args.bare:
        print(json.dumps(bare_client(args.bare, args.seconds, not args.bare_without_friction)), flush=True)
        return 0
    import tempfile

    logdir = args.logs or tempfile.mkdtemp(prefix="sctd-bench-robot-")
    host = free_loopback()
    try:
        with Child("franky_sim.run_server", "--simulator", "mujoco", "--hostname", host,
                   log=Path(logdir) / "franky-sim.log") as sim:
            if not wait_listening(host, 1337, sim, 60):
                return fail("bench robot", f"franky-sim did not start; see {logdir}", EXIT_FAILED)
            floor = _phase_floor(host, args.seconds, logdir)
            unfrictioned = _phase_floor(host, args.seconds, logdir, friction=False)
            ours = sctd_path(host, args.seconds, logdir)
    except RuntimeError as e:
        return fail("bench robot", str(e), EXIT_FAILED)
    if args.json:
        print(json.dumps({"floor": floor, "floor_without_friction": unfrictioned, "sctd": ours,
                          "logs": logdir}))
        return 0
    _print(floor, ours)
    t = unfrictioned["tracking_mm"]
    print(f"  the bare client without friction compensation: hand to reference p50 {t['p50']:.3f} "
          f"p99 {t['p99']:.3f} mm")
    return 0


def _print(floor: dict[str, Any], ours: dict[str, Any]) -> None:
    def row(name: str, a: dict[str, float], b: dict[str, float], unit: str) -> None:
        print(f"  {name:34s} p50 {a['p50']:8.3f} p99 {a['p99']:8.3f} {unit}   |   "
              f"p50 {b['p50']:8.3f} p99 {b['p99']:8.3f} {unit}")
    print("sctd bench robot --driver franky (against franky-sim on this machine)")
    print(f"  {'':34s} {'bare franky client (floor)':30s}   |   sctd run + sctd robot franky")
    row("reference age when handed to franky", floor["reference_age_ms"], ours["target_latency_ms"], "ms")
    row("hand to reference", floor["tracking_mm"], ours["tracking_mm"], "mm")
    print(f"  {'CPU of the client / driver process':34s} {floor['cpu_cores']:.3f} cores{'':17s}|   "
          f"{ours['cpu_cores']:.3f} cores")
    print(f"  {'franky-sim states per wall second':34s} {floor['states_per_s']:.0f}{'':26s}|   "
          f"{ours['states_per_s']:.0f}")
    print("  (sctd's reference age is from the daemon's target stamp: the daemon's tick, Zenoh and the "
          "driver's loop; the floor's from computing it)")


if __name__ == "__main__":
    p = argparse.ArgumentParser(prog="sctd bench robot")
    add_bench_robot_arguments(p)
    sys.exit(main_bench_robot(p.parse_args()))
