"""Simulator figures: real-time factor, step response, tracking error (``sctd bench sim``).

All motion figures are measured in simulated time along the full data path (controller
-> CAN frames -> drives -> Pinocchio -> CAN frames -> controller), so they are the
same on every machine; only the real-time factor depends on the host.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import statistics
import time
from typing import Any

import numpy as np

from sctd import se3
from sctd.app.errors import fail
from sctd.task import Task, TaskError, find_task
from sctd_sim.arm import SimArm
from sctd_sim.robot import ArmModel, load_arm_model
from sctd_sim.simulation import Simulation, start_posture

BENCH_CENTRE = se3.transform_from_rt(np.diag([-1.0, 1.0, -1.0]), [0.50, 0.0, 0.35])
"""Centre of the benchmark motions: hand pointing down in mid-workspace."""


def _arm_at(T_world_ee: np.ndarray, rate: float, arm: ArmModel | None = None) -> SimArm:
    model = arm or load_arm_model()
    return SimArm(model, start_posture(model, T_world_ee), rate=rate)


def measure_rtf(seconds: float = 3.0, rate: float = 1000.0, chunk: float = 0.25) -> dict[str, Any]:
    """Real-time factor of the arm holding still, with the full bus path.

    Runs ``seconds`` of simulated time in chunks of ``chunk`` seconds and reports the
    overall factor and the best chunk's (the best is what the code can do when the host
    is not busy with something else).
    """
    with SimArm(rate=rate) as arm:
        arm.run(0.05)  # warm up caches and allocators
        n_chunks = max(1, round(seconds / chunk))
        walls = []
        for _ in range(n_chunks):
            t0 = time.perf_counter()
            arm.run(chunk)
            walls.append(time.perf_counter() - t0)
    cycles = round(chunk * rate)
    per_cycle = [w / cycles for w in walls]
    return {
        "rate_hz": rate,
        "sim_seconds": n_chunks * chunk,
        "rtf": n_chunks * chunk / sum(walls),
        "rtf_best_chunk": chunk / min(walls),
        "cycle_us_median": 1e6 * statistics.median(per_cycle),
        "cycle_us_best": 1e6 * min(per_cycle),
        "frames_per_cycle": 1 + 2 * 7,
    }


_PARTS = {
    "controller": (("controller", "update"),),
    "bus_controller_end": (("master", "command_frames"), ("master", "send"),
                           ("master", "receive")),
    "bus_drives_end": (("drives", "receive"), ("drives", "output"), ("drives", "state_frames"),
                       ("drives", "send")),
    "physics": (("dynamics", "step"),),
}
"""The parts of a cycle: the ``SimArm`` component methods each is made of."""


def measure_breakdown(seconds: float = 1.0, rate: float = 1000.0, scene: Task | None = None
                      ) -> dict[str, float]:
    """Per-cycle cost of the cycle's parts, us (mean over cycles, like the real-time
    factor, so it includes the controller's damping update every few cycles).

    Times the component methods of :data:`_PARTS` (the controller's torque law; the
    bus work of each end: encoding, sending, receiving and checking frames, and the
    drives' brake and saturation logic; the physics step) with the arm holding still,
    as :func:`measure_rtf` runs it. ``other`` is what the cycle spends outside them
    (and in the timers), ``cycle`` the whole timed cycle: a few microseconds more than
    an untimed one.

    With ``scene`` (a task) the cycle is the simulation's in that
    scene, as the ``sctd sim`` service and lockstep evaluation run it: a target (the
    start pose) given every cycle, then :meth:`Simulation.step
    <sctd_sim.simulation.Simulation.step>`; two more parts are timed, ``target``
    (:meth:`Simulation.set_target <sctd_sim.simulation.Simulation.set_target>`) and
    ``scene`` (the scene's own step: the load, the contents, contacts and handles).
    """
    with contextlib.ExitStack() as stack:
        if scene is None:
            arm = stack.enter_context(SimArm(rate=rate))
            cycle = arm.step
            extra: dict[str, tuple[Any, str]] = {}
        else:
            sim = stack.enter_context(Simulation(scene=scene, rate=rate))
            arm = sim.arm
            pose0 = se3.pose_from_transform(arm.T_world_ee).tolist()

            def cycle() -> None:
                sim.set_target(pose0, sim.t)
                sim.step()
            extra = {"target": (sim, "set_target"), "scene": (sim.scene, "step")}
        arm.run(0.05)
        return _timed_cycles(arm, cycle, extra, max(1, round(seconds * rate)))


def _timed_cycles(arm: SimArm, cycle: Any, extra: dict[str, tuple[Any, str]], n: int
                  ) -> dict[str, float]:
    """Mean us per cycle of each part (:data:`_PARTS` and ``extra``: part -> (object,
    method)), ``other`` and the whole ``cycle`` over ``n`` calls of ``cycle()``."""
    calls = {part: [(getattr(arm, owner), method) for owner, method in m] for part, m in _PARTS.items()}
    calls.update({part: [where] for part, where in extra.items()})
    spent = dict.fromkeys(calls, 0.0)
    pc = time.perf_counter

    def timed(fn: Any, part: str) -> Any:
        def call(*args: Any, **kwargs: Any) -> Any:
            t0 = pc()
            out = fn(*args, **kwargs)
            spent[part] += pc() - t0
            return out
        return call

    for part, where in calls.items():
        for obj, method in where:
            setattr(obj, method, timed(getattr(obj, method), part))
    rows: dict[str, list[float]] = {part: [] for part in (*calls, "other", "cycle")}
    for _ in range(n):
        for part in spent:
            spent[part] = 0.0
        t0 = pc()
        cycle()
        total = pc() - t0
        for part, x in spent.items():
            rows[part].append(x)
        rows["other"].append(total - sum(spent.values()))
        rows["cycle"].append(total)
    return {part: 1e6 * statistics.fmean(x) for part, x in rows.items()}


def step_response(axis: int = 0, size: float = 0.05, rate: float = 1000.0,
                  duration: float = 1.5, tolerance: float = 1e-3) -> dict[str, Any]:
    """Response of the ee to a step of the target along world ``axis``.

    Returns settling time (last time the position error exceeded ``tolerance``),
    overshoot (largest travel past the target along the step, m) and the final error.
    """
    with _arm_at(BENCH_CENTRE, rate) as arm:
        arm.run(0.1)
        T0 = arm.T_world_ee
        T_target = T0.copy()
        T_target[axis, 3] += size
        direction = np.zeros(3)
        direction[axis] = np.sign(size)
        n = round(duration * rate)
        err = np.empty(n)
        past = np.empty(n)
        for k in range(n):
            arm.set_target(T_target, stamp=arm.t)
            arm.step()
            d = arm.dynamics.ee_transform()[:3, 3] - T_target[:3, 3]
            err[k] = np.linalg.norm(d)
            past[k] = d @ direction
    above = np.nonzero(err > tolerance)[0]
    settle = 0.0 if above.size == 0 else (above[-1] + 1) / rate
    return {
        "axis": "xyz"[axis],
        "step_m": size,
        "settling_time_s": float(settle) if settle < duration else float("inf"),
        "overshoot_m": float(max(0.0, past.max())),
        "final_error_m": float(err[-1]),
    }


def _trapezoid(t: float, speed: float, distance: float, ramp: float) -> float:
    """Distance travelled at time ``t`` along a trapezoidal profile: accelerate over
    ``ramp`` seconds to ``speed``, cruise, decelerate over ``ramp``, stop at ``distance``."""
    accel = speed / ramp
    t_total = distance / speed + ramp
    if t < ramp:
        return 0.5 * accel * t * t
    if t < t_total - ramp:
        return 0.5 * accel * ramp * ramp + speed * (t - ramp)
    if t < t_total:
        tr = t_total - t
        return distance - 0.5 * accel * tr * tr
    return distance


def tracking(speed: float = 0.25, distance: float = 0.25, axis: int = 1, rate: float = 1000.0,
             ramp: float = 0.1) -> dict[str, Any]:
    """Error of the ee following a target moving along a line at ``speed``.

    The line runs along world ``axis`` through :data:`BENCH_CENTRE`, ``distance`` long.
    The target accelerates over ``ramp`` seconds, cruises, decelerates and stops (a
    trapezoidal profile, as a teleoperated target would look). Reports the largest and
    RMS position error during the motion and during the cruise phase alone.
    """
    direction = np.zeros(3)
    direction[axis] = 1.0
    T_start = BENCH_CENTRE.copy()
    T_start[:3, 3] -= 0.5 * distance * direction
    with _arm_at(T_start, rate) as arm:
        arm.run(0.1)
        T0 = arm.T_world_ee
        t_cruise = distance / speed - ramp
        t_total = t_cruise + 2 * ramp
        n = round((t_total + 0.3) * rate)
        errs, cruise = [], []
        for k in range(n):
            t = (k + 1) / rate
            s = _trapezoid(t, speed, distance, ramp)
            T = T0.copy()
            T[:3, 3] += s * direction
            arm.set_target(T, stamp=t)
            arm.step()
            e = float(np.linalg.norm(arm.dynamics.ee_transform()[:3, 3] - T[:3, 3]))
            if t <= t_total:
                errs.append(e)
                if ramp <= t < ramp + t_cruise:
                    cruise.append(e)
    e_all, e_cruise = np.array(errs), np.array(cruise)
    return {
        "speed_m_s": speed,
        "axis": "xyz"[axis],
        "max_error_m": float(e_all.max()),
        "rms_error_m": float(np.sqrt(np.mean(e_all**2))),
        "cruise_max_error_m": float(e_cruise.max()),
    }


def scene_step(scene: Task, size: float = 0.05, rate: float = 1000.0, duration: float = 2.5,
               tolerance: float = 1e-3, hold: float = 1.0, compensate: bool = True) -> dict[str, Any]:
    """A step of the target along world x from the scene's start pose, with the scene in
    the loop (the full bottle in the pour scene, held by a controller that knows its
    load as it empties; the free hand in front of the drawer). Settling: the last time
    the error exceeded ``tolerance``. ``hold`` seconds of holding the start come first."""
    with Simulation(scene=scene, rate=rate, compensate_payload=compensate) as sim:
        T0 = sim.arm.T_world_ee
        pose0 = se3.pose_from_transform(T0)
        for _ in range(round(hold * rate)):
            sim.set_target(pose0, sim.t)
            sim.step()
        sag = float(np.linalg.norm(sim.arm.dynamics.ee_transform()[:3, 3] - T0[:3, 3]))
        T_target = T0.copy()
        T_target[0, 3] += size
        pose = se3.pose_from_transform(T_target)
        n = round(duration * rate)
        err = np.empty(n)
        past = np.empty(n)
        for k in range(n):
            sim.set_target(pose, sim.t)
            sim.step()
            d = sim.arm.dynamics.ee_transform()[:3, 3] - T_target[:3, 3]
            err[k] = np.linalg.norm(d)
            past[k] = d[0] * np.sign(size)
        payload = sim.scene.payload()
    above = np.nonzero(err > tolerance)[0]
    settle = 0.0 if above.size == 0 else (above[-1] + 1) / rate
    return {
        "scene": scene.name,
        "compensated": compensate,
        "payload_kg": None if payload is None else float(payload[0]),
        "hold_error_m": sag,
        "step_m": size,
        "settling_time_s": float(settle) if settle < duration else float("inf"),
        "overshoot_m": float(max(0.0, past.max())),
        "final_error_m": float(err[-1]),
    }


def scene_tracking(scene: Task, speed: float = 0.1, distance: float = 0.15, rate: float = 1000.0,
                   ramp: float = 0.1) -> dict[str, Any]:
    """Error of the hand following a target moving along world y from the scene's start
    at ``speed`` (trapezoidal, as :func:`tracking`), with the scene in the loop."""
    with Simulation(scene=scene, rate=rate) as sim:
        T0 = sim.arm.T_world_ee
        for _ in range(round(0.5 * rate)):
            sim.set_target(se3.pose_from_transform(T0), sim.t)
            sim.step()
        t_total = distance / speed + ramp
        errs = []
        for k in range(round(t_total * rate)):
            T = T0.copy()
            T[1, 3] += _trapezoid((k + 1) / rate, speed, distance, ramp)
            sim.set_target(se3.pose_from_transform(T), sim.t)
            sim.step()
            errs.append(float(np.linalg.norm(sim.arm.dynamics.ee_transform()[:3, 3] - T[:3, 3])))
    e = np.array(errs)
    return {"scene": scene.name, "speed_m_s": speed, "axis": "y", "max_error_m": float(e.max()),
            "rms_error_m": float(np.sqrt(np.mean(e**2)))}


def run_scene_bench(scene: Task, rate: float = 1000.0) -> dict[str, Any]:
    """The step (5 cm along world x) and tracking figures in ``scene``, the targets
    (settles below 1 mm in under 1 s, as in the empty workspace) and the cost of a cycle
    in the scene (``breakdown``, :func:`measure_breakdown`)."""
    step = scene_step(scene, 0.05, rate)
    track = scene_tracking(scene, 0.1, 0.15, rate)
    bare = scene_step(scene, 0.05, rate, compensate=False) if step["payload_kg"] is not None else None
    breakdown = measure_breakdown(1.0, rate, scene)
    return {"scene": scene.name, "step": step, "tracking": track, "uncompensated_step": bare,
            "breakdown": breakdown,
            "pass": {"settle<1s": step["settling_time_s"] < 1.0,
                     "final<1mm": step["final_error_m"] < 1e-3,
                     "tracking<5mm": track["max_error_m"] < 5e-3}}


def format_scene_report(result: dict[str, Any]) -> str:
    """Human-readable report of :func:`run_scene_bench`'s result."""
    s, t = result["step"], result["tracking"]
    load = "no load" if s["payload_kg"] is None else f"payload {s['payload_kg']:.2f} kg compensated"
    lines = [
        f"scene {result['scene']} ({load}): holding the start {s['hold_error_m'] * 1e3:.2f} mm off",
        f"5 cm step along x: settles < 1 mm in {s['settling_time_s'] * 1e3:.0f} ms, overshoot "
        f"{s['overshoot_m'] * 1e3:.2f} mm, final error {s['final_error_m'] * 1e3:.3f} mm",
        f"tracking {t['speed_m_s']:.2f} m/s along y: max {t['max_error_m'] * 1e3:.2f} mm, "
        f"rms {t['rms_error_m'] * 1e3:.2f} mm",
    ]
    b = result.get("uncompensated_step")
    if b is not None:
        lines.append(
            f"  the same step without telling the controller the load (baseline): holding "
            f"{b['hold_error_m'] * 1e3:.2f} mm off, settles < 1 mm in "
            + ("never (within 2.5 s)" if b["settling_time_s"] == float("inf") else
               f"{b['settling_time_s'] * 1e3:.0f} ms")
            + f", final error {b['final_error_m'] * 1e3:.3f} mm")
    if result.get("breakdown"):
        lines.append(parts_line(result["breakdown"]))
    lines.append("targets: " + ", ".join(f"{k} {'ok' if v else 'MISSED'}" for k, v in result["pass"].items()))
    return "\n".join(lines)


def parts_line(b: dict[str, float]) -> str:
    """One line of :func:`measure_breakdown`'s figures (with a scene's parts, if any)."""
    scene = "".join(f", {part} {b[part]:.0f}" for part in ("target", "scene") if part in b)
    return (f"cycle parts (mean us): controller {b['controller']:.0f}, bus "
            f"{b['bus_controller_end'] + b['bus_drives_end']:.0f} (controller end "
            f"{b['bus_controller_end']:.0f}, drives end {b['bus_drives_end']:.0f}), physics "
            f"{b['physics']:.0f}{scene}, other {b['other']:.0f}; whole timed cycle {b['cycle']:.0f}")


def run_bench(seconds: float = 3.0, rate: float = 1000.0) -> dict[str, Any]:
    """All simulator figures.

    Parameters
    ----------
    seconds : float, optional
        Simulated time of the real-time-factor run.
    rate : float, optional
        Cycle rate, Hz.

    Returns
    -------
    dict
        ``rtf`` (see :func:`measure_rtf`), ``breakdown`` (see
        :func:`measure_breakdown`), ``step`` (one entry per axis, see
        :func:`step_response`), ``tracking`` (one entry per axis, see :func:`tracking`),
        and ``pass`` with the targets checked.
    """
    rtf = measure_rtf(seconds, rate)
    breakdown = measure_breakdown(min(seconds, 1.0), rate)
    steps = [step_response(axis, 0.05, rate) for axis in range(3)]
    tracks = [tracking(0.25, 0.25, axis, rate) for axis in range(3)]
    worst_settle = max(s["settling_time_s"] for s in steps)
    worst_over = max(s["overshoot_m"] for s in steps)
    worst_track = max(t["max_error_m"] for t in tracks)
    return {
        "rtf": rtf,
        "breakdown": breakdown,
        "step": steps,
        "tracking": tracks,
        "pass": {
            "rtf>=4": rtf["rtf"] >= 4.0,
            "settle<1s": worst_settle < 1.0,
            "overshoot<2mm": worst_over < 2e-3,
            "tracking<5mm": worst_track < 5e-3,
        },
    }


def format_report(result: dict[str, Any]) -> str:
    """Human-readable report of :func:`run_bench`'s result."""
    r = result["rtf"]
    lines = [
        f"real-time factor at {r['rate_hz']:.0f} Hz (full CAN path, {r['frames_per_cycle']} "
        f"frames/cycle, {r['sim_seconds']:.1f} s simulated): {r['rtf']:.2f} "
        f"(best chunk {r['rtf_best_chunk']:.2f}; cycle median {r['cycle_us_median']:.0f} us)",
    ]
    b = result.get("breakdown")
    if b:
        lines.append(parts_line(b))
    for s in result["step"]:
        lines.append(
            f"5 cm step along {s['axis']}: settles < 1 mm in {s['settling_time_s'] * 1e3:.0f} ms, "
            f"overshoot {s['overshoot_m'] * 1e3:.2f} mm, final error {s['final_error_m'] * 1e3:.3f} mm")
    for t in result["tracking"]:
        lines.append(
            f"tracking {t['speed_m_s']:.2f} m/s along {t['axis']}: max {t['max_error_m'] * 1e3:.2f} mm, "
            f"rms {t['rms_error_m'] * 1e3:.2f} mm, cruise max {t['cruise_max_error_m'] * 1e3:.2f} mm")
    lines.append("targets: " + ", ".join(f"{k} {'ok' if v else 'MISSED'}"
                                         for k, v in result["pass"].items()))
    return "\n".join(lines)


def add_bench_sim_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``sctd bench sim``."""
    p.add_argument("--seconds", type=float, default=3.0,
                   help="simulated seconds of the real-time-factor run (default %(default)s)")
    p.add_argument("--rate", type=float, default=1000.0, help="cycle rate, Hz (default %(default)s)")
    p.add_argument("--scene", metavar="NAME|FILE", default=None,
                   help="measure the step (5 cm along world x) and tracking in the scene of this task "
                        "(the path of a task file, or the name of a shipped or registered one; sctd tasks "
                        "lists them), with its load, instead of the empty-workspace figures")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def main_bench_sim(args: argparse.Namespace) -> int:
    if args.seconds <= 0 or args.rate <= 0:
        return fail("bench sim", "--seconds, --rate: must be > 0")
    if args.scene is not None:
        try:
            task = find_task(args.scene)
        except TaskError as e:
            return fail("bench sim", f"--scene: {e}")
        result = run_scene_bench(task, args.rate)
        print(json.dumps(result, default=float) if args.json else format_scene_report(result))
        return 0
    result = run_bench(args.seconds, args.rate)
    if args.json:
        print(json.dumps(result, default=float))
    else:
        print(format_report(result))
    return 0
