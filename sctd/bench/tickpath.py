"""The daemon's tick path in one process, from bytes: what the tick thread's own work costs
without Zenoh, hot and after a sleep (``sctd bench cost``'s tick-path rows).

Per tick, timed on this thread's CPU clock: the robot state off the wire
(:meth:`~sctd.runtime.driver.TickDriver.receive`: decoded, judged, kept), the object poses
every :data:`OBJECT_EVERY` ticks and an input message every :data:`INPUT_EVERY` (the
bench's person: centred with the deadman released, or sines over the whole range with
it held), the control step, the target encoded (and a gripper message when the tick has
one), the between-ticks work. Untimed: the state each tick is made from the previous
target (an arm that follows it exactly), and, with ``--sleep-us``, a sleep before each
tick as the daemon's tick thread sleeps between its ticks. ``--split`` also times the
path's parts on the same clock (:data:`SPLIT`). ``--path floor`` times what
the bench's floor peer does instead (the state decoded, a target encoded), and ``--path
loop`` a control: arithmetic on a few locals, as long as a tick, touching almost no memory.

The figures say what sleeping costs the code after it: on this project's VMs the tick
path costs 1.5 to 4 times as much after a 0.9 ms sleep as back to back, and the control
loop the same either way, so what a sleep costs is the memory a tick touches, fetched
again (docs/benchmarks.md). It runs as a module of its own (``python -m sctd_tickpath``, a copy) in
another source tree's environment too, so it reads only that tree's public interfaces.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from typing import Any

OBJECT_EVERY = 20  # ticks between object poses (50 Hz)
INPUT_EVERY = 10  # ticks between input messages (100 Hz, the bench's person)
LOOP_STEPS = 600  # the control loop's steps (--path loop)
WARMUP = 1000  # ticks before the measured ones
SPLIT = ("receive", "update", "command", "controller", "encode", "after")
"""The tick path's parts with ``--split``: the messages taken (decoded, judged, kept), the
skill's FSM (``SkillEngine.update``), its input mappings and constraints
(``SkillEngine.command``), the rest of the control step (the gates, the safety limits,
the target's pose: ``TickDriver.tick`` less the two before), the target encoded, the
work between ticks. Each timer costs about a microsecond, which the parts carry."""
BLOCK = 250  # measured ticks per block: the figure is the median of the blocks' means, so
# that a burst of another program's work on a shared machine moves it by a block at most


def clock_cost(n: int = 2000) -> float:
    """The median cost (s) of one pair of CPU-clock reads, taken off each tick's time."""
    clock = time.thread_time
    pairs = []
    for _ in range(n):
        a = clock()
        pairs.append(clock() - a)
    return statistics.median(pairs)


class _Bench:
    """One skill's driver and the untimed messages around its ticks (module doc)."""

    def __init__(self, skill_path: str, task_name: str, full: bool):
        from sctd.runtime.controller import RuntimeConfig
        from sctd.runtime.driver import TickDriver
        from sctd.skill import load_skill
        from sctd.skill.catalog import find_skill
        from sctd.task import find_task
        from sctd.wire import codec
        from sctd_sim.simulation import Simulation, trial_scene

        scene, q0 = trial_scene(find_task(task_name), 0)
        with Simulation(scene=scene, q0=q0) as sim:  # only its first state and poses
            self.m, self.poses = sim.state_message(), sim.objects()
        self.codec: Any = codec  # the wire codec (its target encoders timed with --split)
        self.full = full
        self.driver = TickDriver(load_skill(find_skill(skill_path)), RuntimeConfig())
        self.pose: list[float] = list(self.m["pose"])  # the newest target: the arm follows it
        self.modes: dict[str, int] = {}
        self.split: dict[str, float] | None = None

    def time_parts(self) -> None:
        """From now on, add each part's CPU time (:data:`SPLIT`) to :attr:`split`; the
        control step's own share is worked out at the end (:meth:`parts_us`)."""
        self.split = split = dict.fromkeys((*SPLIT, "tick"), 0.0)
        clock = time.thread_time

        def timed(part: str, f: Any) -> Any:
            def timed_call(*args: Any) -> Any:
                t0 = clock()
                try:
                    return f(*args)
                finally:
                    split[part] += clock() - t0
            return timed_call

        driver, engine = self.driver, self.driver.engine
        driver.receive = timed("receive", driver.receive)  # type: ignore[method-assign]
        driver.tick = timed("tick", driver.tick)  # type: ignore[method-assign]
        driver.after_tick = timed("after", driver.after_tick)  # type: ignore[method-assign]
        engine.update = timed("update", engine.update)  # type: ignore[method-assign]
        engine.command = timed("command", engine.command)  # type: ignore[method-assign]
        codec = self.codec
        self.codec = type("TimedCodec", (), {  # the module's encoders, the target's timed
            **{f: staticmethod(getattr(codec, f))
               for f in ("encode_state", "encode_object", "encode_input", "decode_state")},
            "encode_target": staticmethod(timed("encode", codec.encode_target)),
            "encode_gripper": staticmethod(timed("encode", codec.encode_gripper))})

    def parts_us(self, ticks: int) -> dict[str, float]:
        """:attr:`split` as us a tick over ``ticks``, the controller's share worked out."""
        assert self.split is not None
        us = {k: 1e6 * v / ticks for k, v in self.split.items()}
        us["controller"] = us.pop("tick") - us["update"] - us["command"]
        return {k: round(us[k], 2) for k in SPLIT}

    def messages(self, k: int, wall: float) -> tuple[bytes, list[tuple[str, bytes]], bytes | None]:
        """Tick ``k``'s state (at the newest target), its object poses and input, if due."""
        codec, m = self.codec, self.m
        state = codec.encode_state(k, wall, self.pose, q=m["q"], dq=m["dq"], wrench=m["wrench"],
                                   gripper=m.get("gripper"))
        objects = [(n, codec.encode_object(k, wall, p)) for n, p in self.poses.items()] \
            if k % OBJECT_EVERY == 1 else []
        given = None
        if k % INPUT_EVERY == 1:
            j = k // INPUT_EVERY + 1
            u = [math.sin(j * 0.013), math.cos(j * 0.009), math.sin(j * 0.005)] if self.full else [0.0] * 3
            given = codec.encode_input(j, wall, u, [0, 1 if self.full else 0, 0])
        return state, objects, given

    def tick(self, wall: float, state: bytes, objects: list[tuple[str, bytes]], given: bytes | None) -> str:
        """The tick thread's work for one tick (timed by the caller); its mode."""
        driver, codec = self.driver, self.codec
        now = time.monotonic()
        driver.receive("state", "", state, now)
        for name, data in objects:
            driver.receive("object", name, data, now)
        if given is not None:
            driver.receive("input", "bench", given, now)
        res = driver.tick(now, wall)
        if res.pose is not None:
            codec.encode_target(driver.target_seq, wall, res.pose, res.state, driver.controller.skill.id,
                                res.in_seq, res.device, res.seed)
            self.pose = res.pose
        if res.gripper is not None:
            codec.encode_gripper(res.gripper)
        driver.after_tick()
        return res.mode

    @staticmethod
    def loop() -> float:
        """The control: arithmetic on a few locals, about as long as the zero-input tick
        back to back, touching almost no memory."""
        s = 0.0
        for i in range(LOOP_STEPS):
            s += i * 0.5
        return s

    def floor(self, k: int, wall: float, state: bytes) -> None:
        """The floor peer's work for one tick: the state decoded, a target encoded."""
        self.codec.decode_state(state)
        self.codec.encode_target(k, wall, self.pose, "floor", "floor", 0, "", False)


def measure(skill_path: str, task_name: str, full: bool, ticks: int, sleep_s: float,
            path: str = "tick", split: bool = False) -> dict[str, Any]:
    """CPU per tick (us) of the tick path (``path`` ``tick``) or the floor's (``floor``):
    the median over blocks of :data:`BLOCK` of ``ticks`` ticks after :data:`WARMUP` of
    the mean, each tick after a sleep of ``sleep_s``. ``split`` (the tick path only):
    also its parts (:data:`SPLIT`), the mean over the measured ticks, in ``split``."""
    bench, clock, spent, blocks = _Bench(skill_path, task_name, full), time.thread_time, 0.0, []
    if split and path != "tick":
        raise ValueError(f"--split times the tick path's parts, not --path {path}'s")
    for k in range(1, WARMUP + ticks + 1):
        if split and k == WARMUP + 1:
            bench.time_parts()
        if sleep_s > 0.0:
            time.sleep(sleep_s)
        wall = time.time()
        state, objects, given = bench.messages(k, wall)
        t0 = clock()
        if path == "floor":
            bench.floor(k, wall, state)
        elif path == "loop":
            bench.loop()
        else:
            mode = bench.tick(wall, state, objects, given)
        if k > WARMUP:
            spent += clock() - t0
            if path == "tick":
                bench.modes[mode] = bench.modes.get(mode, 0) + 1
            if (k - WARMUP) % BLOCK == 0 or k == WARMUP + ticks:
                blocks.append(spent / (BLOCK if (k - WARMUP) % BLOCK == 0 else (k - WARMUP) % BLOCK))
                spent = 0.0
    us = 1e6 * (statistics.median(blocks) - clock_cost())
    row = {"skill": skill_path, "task": task_name, "input": "full" if full else "zero", "path": path,
           "ticks": ticks, "sleep_us": round(sleep_s * 1e6, 1), "us_per_tick": round(us, 2),
           "modes": bench.modes}
    return row if not split else row | {"split": bench.parts_us(ticks)}


def main(argv: list[str] | None = None) -> int:
    """``python -m sctd.bench.tickpath`` (or ``sctd_tickpath``, a copy): one JSON line, the
    rows of every input and sleep asked for, in that order."""
    p = argparse.ArgumentParser(prog="sctd_tickpath", description=__doc__.splitlines()[0])
    p.add_argument("--skill", required=True, help="the skill: a file, or a shipped or stored skill's name")
    p.add_argument("--task", required=True, help="the task whose first trial's scene gives the state")
    p.add_argument("--inputs", default="zero,full", help="zero and/or full (default %(default)s)")
    p.add_argument("--path", choices=["tick", "floor", "loop"], default="tick")
    p.add_argument("--ticks", type=int, default=3000)
    p.add_argument("--sleeps-us", default="0", help="comma-separated sleeps before each tick (default 0)")
    p.add_argument("--split", action="store_true",
                   help="also time the tick path's parts (receive, update, command, controller, encode, "
                        "after; each timer adds about 1 us to its part)")
    a = p.parse_args(argv)
    inputs = [x.strip() for x in a.inputs.split(",") if x.strip()]
    try:
        sleeps = [float(x) for x in a.sleeps_us.split(",") if x.strip()]
    except ValueError:
        p.error(f"--sleeps-us {a.sleeps_us!r}: comma-separated numbers")
    if a.ticks < 1 or not sleeps or min(sleeps) < 0 or not inputs or set(inputs) - {"zero", "full"}:
        p.error("--ticks must be >= 1, --sleeps-us numbers >= 0, --inputs zero and/or full")
    if a.split and a.path != "tick":
        p.error(f"--split times the tick path's parts, not --path {a.path}'s")
    rows = [measure(a.skill, a.task, x == "full", a.ticks, us * 1e-6, a.path, a.split)
            for x in inputs for us in sleeps]
    print(json.dumps({"rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
