"""A simulated user: a closed-loop input client that steers a skill towards goals.

It asks the daemon for the active skill (the ``skill`` query), watches the target
(FSM state) and the robot state, and each cycle sends the input that the active state's
linear input mappings turn into the motion it wants: ``u = pinv(M) d*`` for a desired
displacement ``d*`` of the mapping's frame towards a per-state goal (for a
vector-field state, the translation direction towards the goal). It also measures the
input -> target latency: the time from sending input ``seq`` to receiving the first
target whose ``in_seq`` is ``seq``.

    python -m sctd_services.simulated_user --task pour --connect tcp/127.0.0.1:7447
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np
import zenoh

from sctd import se3
from sctd.runtime import codec
from sctd.runtime.timing import Histogram, Ticker, set_timer_slack
from sctd.runtime.zsession import add_zenoh_arguments, session_from_args


@dataclass(frozen=True)
class Goal:
    """Where the user wants ``frame`` (object frame): position, and a tilt about the
    frame's own y axis (z towards x: pouring forwards) at its current heading."""

    frame: str
    position: tuple[float, float, float]
    tilt: float = 0.0


# Per task and FSM state; states not listed use the task's "*" entry.
GOALS: dict[str, dict[str, Goal]] = {
    "pour": {
        "carry": Goal("tip", (0.0, 0.0, 0.08)),
        "approach": Goal("tip", (0.0, 0.0, 0.05), tilt=0.5),
        "pour": Goal("tip", (0.0, 0.0, 0.06), tilt=1.6),
        "*": Goal("tip", (0.0, 0.0, 0.06), tilt=1.6),
    },
    "drawer": {
        "reach": Goal("ee", (0.0, 0.0, 0.0)),
        "pull": Goal("ee", (0.30, 0.0, 0.0)),  # pull the drawer 0.3 m open
        "*": Goal("ee", (0.0, 0.0, 0.0)),
    },
}


class Policy:
    """Turns (skill summary, state, T_obj_ee) into an input vector."""

    def __init__(self, summary: dict, task: str, gain_distance: float = 0.03, gain_angle: float = 0.2):
        self.summary = summary
        self.goals = GOALS[task]
        self.gain_distance = gain_distance
        self.gain_angle = gain_angle
        self.frames = {n: se3.transform_from_pose(f["pose"]) for n, f in summary["frames"].items()}
        lim = summary["limits"]
        self.speeds = np.array([lim["max_linear_speed"]] * 3 + [lim["max_angular_speed"]] * 3)
        self.states = {s["name"]: s for s in summary["states"]}

    def command(self, state: str, T_obj_ee: np.ndarray, done: bool = False) -> np.ndarray:
        """Input for the active ``state``; ``done``: the task is achieved (the mug holds
        enough), so the user brings the bottle back upright where it is."""
        goal = self.goals.get(state, self.goals["*"])
        if done:
            goal = Goal(goal.frame, goal.position, tilt=0.0)
        T_ee_f = self.frames.get(goal.frame, np.eye(4))
        T_f = T_obj_ee @ T_ee_f
        dp = np.asarray(goal.position) - T_f[:3, 3]
        heading = math.atan2(T_f[1, 0], T_f[0, 0])
        R_goal = se3.matrix_from_rotvec([0.0, 0.0, heading]) @ se3.matrix_from_rotvec([0.0, goal.tilt, 0.0])
        dr = se3.rotvec_from_matrix(T_f[:3, :3].T @ R_goal)
        # Saturating P-control: full input beyond gain_distance / gain_angle of error.
        want = np.concatenate([dp / self.gain_distance, dr / self.gain_angle]) * self.speeds
        ims = self.states.get(state, {}).get("input_mappings", [])
        linear = [m for m in ims if m["type"] == "linear"]
        if linear:
            M = np.asarray(linear[0]["matrix"]) * self.speeds[:, None]
            u = np.linalg.lstsq(M, want, rcond=None)[0]
        else:
            u = dp / max(self.gain_distance, float(np.linalg.norm(dp)))
        u = np.nan_to_num(u)
        peak = float(np.max(np.abs(u))) if len(u) else 0.0
        if peak > 1.0:
            u = u / peak
        out = np.zeros(3)
        out[: min(3, len(u))] = u[:3]
        return out


def fetch_summary(session: zenoh.Session, keys: codec.Keys, timeout: float = 2.0) -> dict | None:
    for reply in session.get(keys.skill, timeout=timeout):
        if reply.ok is not None:
            return msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False)
    return None


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="sctd-simulated-user", description=__doc__.split("\n\n")[0])
    p.add_argument("--task", default="pour", choices=sorted(GOALS))
    p.add_argument("--robot", default="edan")
    p.add_argument("--device", default="simuser")
    p.add_argument("--rate", type=float, default=250.0, help="input rate, Hz (default %(default)s)")
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--warmup", type=float, default=0.5, help="s of latency samples to discard")
    p.add_argument("--fill", type=float, default=0.5,
                   help="pour: stop pouring once the simulator's scene reports this much poured")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    add_zenoh_arguments(p)
    args = p.parse_args(argv)

    keys = codec.Keys(args.robot)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    sent: dict[int, float] = {}
    latency = Histogram()
    lock = threading.Lock()
    first_target: dict[str, float | None] = {"t": None}
    info: dict[str, Any] = {"state": None, "skill": None, "targets": 0, "changes": [],
                            "T_world_ee": None, "T_world_obj": None}
    t_start = time.monotonic()

    def on_target(sample: zenoh.Sample) -> None:
        now = time.monotonic()
        try:
            msg = codec.decode_target(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        with lock:
            t_sent = sent.pop(msg["in_seq"], None)
            if t_sent is not None and now - t_start > args.warmup:
                latency.add(now - t_sent)
            info["targets"] += 1
            if first_target["t"] is None:
                first_target["t"] = now
            if msg["state"] != info["state"]:
                info["changes"].append((round(now - t_start, 3), info["state"], msg["state"]))
                info["state"] = msg["state"]
            info["skill"] = msg["skill"]

    def on_state(sample: zenoh.Sample) -> None:
        try:
            m = codec.decode_state(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        info["T_world_ee"] = se3.transform_from_pose(m.pose)

    policy: Policy | None = None
    with session_from_args(args) as session:
        sub_t = session.declare_subscriber(keys.target, on_target)
        sub_s = session.declare_subscriber(keys.state, on_state)
        summary_holder: dict = {}

        def on_object(sample: zenoh.Sample) -> None:
            name = str(sample.key_expr).rsplit("/", 1)[-1]
            if summary_holder.get("object") != name:
                return
            try:
                pose = codec.decode_object(sample.payload.to_bytes()).pose
                info["T_world_obj"] = se3.transform_from_pose(pose)
            except codec.DecodeError:
                pass

        sub_o = session.declare_subscriber(keys.objects(), on_object)

        def on_scene(sample: zenoh.Sample) -> None:
            try:
                info["scene"] = codec.unpack_map(sample.payload.to_bytes())
            except codec.DecodeError:
                pass

        sub_sc = session.declare_subscriber(keys.scene, on_scene)
        pub = session.declare_publisher(keys.input(args.device), express=True)
        set_timer_slack(1)
        ticker = Ticker(1.0 / args.rate, spin=0.0)
        end = time.monotonic() + args.duration
        seq = 0
        skill_id = None
        while not stop.is_set() and time.monotonic() < end:
            _now, _ = ticker.wait()
            if policy is None or (info["skill"] is not None and info["skill"] != skill_id):
                summary = fetch_summary(session, keys, timeout=0.5)
                if summary is None:
                    continue
                summary_holder.update(summary)
                policy = Policy(summary, args.task)
                skill_id = summary["id"]
                ticker = Ticker(1.0 / args.rate, spin=0.0)
                continue
            u = np.zeros(3)
            T_ee, T_obj = info["T_world_ee"], info["T_world_obj"]
            if T_ee is not None and T_obj is not None:
                state = info["state"] or summary_holder.get("start", "")
                scene = info.get("scene") or {}
                done = args.task == "pour" and scene.get("poured", 0.0) >= args.fill
                u = policy.command(state, se3.invert_transform(T_obj) @ T_ee, done)
            with lock:
                sent[seq] = time.monotonic()
                if len(sent) > 5000:  # inputs overwritten before any tick used them
                    for k in list(sent)[:1000]:
                        del sent[k]
            pub.put(codec.encode_input(seq, time.time(), u.tolist()))
            seq += 1
        elapsed = time.monotonic() - (first_target["t"] or time.monotonic())
        for d in (sub_t, sub_s, sub_o, sub_sc, pub):
            d.undeclare()
    report = {
        "task": args.task,
        "inputs_sent": seq,
        "targets_received": info["targets"],
        "target_rate": round(info["targets"] / elapsed, 1) if elapsed > 0 else 0.0,
        "state_changes": info["changes"],
        "final_state": info["state"],
        "latency_ms": latency.summary_ms(),
    }
    if args.json:
        print(json.dumps(report))
    else:
        for t, a, b in report["state_changes"]:
            print(f"  t={t:6.2f}s  state {a} -> {b}")
        lat = report["latency_ms"]
        print(f"  targets: {report['targets_received']} ({report['target_rate']} /s); "
              f"input->target latency p50 {lat['p50']} ms, p99 {lat['p99']} ms, max {lat['max']} ms")
    return 0 if not math.isnan(report["target_rate"]) else 1


if __name__ == "__main__":
    sys.exit(main())
