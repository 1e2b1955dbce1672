"""``sctd teach --then-learn METHOD [--swap]``: the loop closed on this machine.

Next to the simulator that ``sctd teach`` starts: a learner service (``sctd learner``)
before the first demonstration, so that it stores each one as it is published; after
the last one, the daemon (``sctd run`` on the scene's hand-written skill: the arm is the
daemon's from then on) and one training request for exactly the demonstrations just
taught; the learner trains, checks and swaps; then the swapped skill is evaluated
(``sctd eval --lockstep``). Every step is printed with its time, and the figure that
matters to whoever teaches: from the last demonstration to the swapped skill.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import tempfile
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import zenoh

from sctd_services.eval.evaluate import entries, evaluate, table
from sctd_services.eval.trial import TaskSpec

from .. import se3
from ..skill import SkillError, load_skill
from ..skill.catalog import find_skill, shipped_folder, shipped_skills
from ..task import Task, TaskError, find_task
from ..wire import Keys, client, codec
from .procs import Child

METHODS = ("linear", "vf")


def candidate_frames(task: Task) -> list[str]:
    """The candidate frames of a linear-IM request on ``task``'s demonstrations: ``tip``,
    the outlet of what the hand holds (the bottle's tip, as its task file puts it in the
    hand's frame), which linear IMs need as a candidate; none for a task whose hand holds
    no contents."""
    held = task.scene.held
    if held is None or held.contents is None:
        return []
    pose = se3.pose_from_transform(held.frames[held.contents.outlet])
    return ["tip=" + ",".join(f"{x:g}" for x in pose)]


def start_skill(task: str) -> str:
    """The skill the daemon runs before the swap: the task's hand-written skill, the one
    named as the task (``sctd run --skill <task>``), else the first shipped skill on the
    task's object (a learned one, for a task nobody wrote a skill for)."""
    try:
        find_skill(task)
        return task
    except SkillError as e:
        why = str(e)
    try:
        obj = find_task(task).object
    except TaskError as e:
        raise LoopError(f"--swap: no skill named as the task {task!r}: {e}") from None
    on_object = [p for p in sorted(shipped_skills()) if load_skill(p).object == obj]
    if not on_object:
        raise LoopError(f"--swap: no skill named as the task {task!r} and no shipped skill on its object "
                        f"{obj!r} to start the daemon on: {why}")
    return str(on_object[0])


def add_then_learn_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("then learn (the learner service, the daemon, the swap)")
    g.add_argument("--then-learn", choices=METHODS, default=None, metavar="METHOD",
                   help="after teaching, have a learner service (started here) train a skill "
                        "from the demonstrations just taught: linear or vf")
    g.add_argument("--swap", action="store_true",
                   help="with --then-learn: start the daemon on the scene's hand-written skill "
                        "after the last demonstration and let the learner check and swap the "
                        "new skill into it")
    g.add_argument("--store", default=None, metavar="DIR",
                   help="the learner's store (default: a temporary one; $SCTD_STORE or the user "
                        "data folder are for the long-running learner)")
    g.add_argument("--check-trials", type=int, default=20,
                   help="at most this many lockstep trials in the learner's check (a sequential "
                        "test; a skill that always succeeds passes after 6) (default %(default)s)")
    g.add_argument("--eval-trials", type=int, default=20,
                   help="lockstep trials of the evaluation of the swapped skill (default "
                        "%(default)s; 0: none)")


class LoopError(RuntimeError):
    """A step of the loop that did not happen (the learner did not start, store or train)."""


class _Watch:
    """The learner's status (stored names by key, the newest state) and the daemon's
    status and targets (for the gap across the swap)."""

    def __init__(self, s: zenoh.Session, keys: Keys) -> None:
        self.stored: dict[str, str] = {}  # published key -> the name the learner stored it as
        self.learner_up = threading.Event()
        self.skill: str | None = None
        self.stamps: list[float] = []  # target stamps, while recording them
        self.recording = False
        self._subs = [s.declare_subscriber(keys.learner_status, self._on_learner),
                      s.declare_subscriber(keys.status, self._on_status),
                      s.declare_subscriber(keys.target, self._on_target)]

    def _on_learner(self, sample: zenoh.Sample) -> None:
        msg = codec.unpack_map(sample.payload.to_bytes())
        if msg.get("event") == "state":
            self.learner_up.set()
        elif msg.get("event") == "swapping":
            self.recording = True  # the daemon's targets across the swap
        elif msg.get("event") in ("stored", "duplicate"):
            self.stored[str(msg.get("key"))] = str(msg.get("name"))

    def _on_status(self, sample: zenoh.Sample) -> None:
        self.skill = codec.unpack_map(sample.payload.to_bytes()).get("skill")

    def _on_target(self, sample: zenoh.Sample) -> None:
        if self.recording:
            self.stamps.append(float(codec.unpack_map(sample.payload.to_bytes())["stamp"]))

    def max_gap_ms(self) -> float | None:
        s = self.stamps
        return max(b - a for a, b in itertools.pairwise(s)) * 1e3 if len(s) > 1 else None

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def _wait(pred: Any, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > end:
            return False
        time.sleep(0.01)
    return True


def start_learner(stack: contextlib.ExitStack, s: zenoh.Session, args: argparse.Namespace,
                  logdir: Path) -> _Watch:
    """The learner service as a child (store, check trials), running before teaching
    starts; the watch on it and the daemon."""
    store = args.store or str(logdir / "store")
    keys = Keys(args.robot)
    watch = _Watch(s, keys)
    stack.callback(watch.close)
    t0 = time.monotonic()
    stack.enter_context(Child("sctd_services.learner", "--store", store, "--robot", args.robot,
                              "--trials", str(args.check_trials), *args.child_zenoh,
                              log=logdir / "learner.log"))
    if not watch.learner_up.wait(60):
        raise LoopError(f"the learner did not start within 60 s; see {logdir / 'learner.log'}")
    print(f"sctd teach: learner up in {time.monotonic() - t0:.1f} s (store {store}, log "
          f"{logdir / 'learner.log'})", flush=True)
    return watch


def _demo_names(watch: _Watch, keys: Keys, scene: str, kept: list[Any]) -> list[str]:
    """The names the learner stored the kept demonstrations as (it renames one whose name
    it already has with other rows)."""
    wanted = [keys.demos(scene, a.name) for a in kept]
    if not _wait(lambda: all(k in watch.stored for k in wanted), 30):
        missing = [k for k in wanted if k not in watch.stored]
        raise LoopError(f"the learner did not store {', '.join(missing)} within 30 s")
    return [watch.stored[k] for k in wanted]


def learn_and_swap(stack: contextlib.ExitStack, s: zenoh.Session, args: argparse.Namespace,
                   scene: str, kept: list[Any], watch: _Watch, logdir: Path) -> dict[str, Any]:
    """After the last demonstration: the daemon (with ``--swap``), the training request
    for the demonstrations just taught, the swap confirmed on the daemon's status; the
    learner's reply, with ``last_demo_to_swap_s`` and ``swap_gap_ms`` added."""
    t_last = time.monotonic()
    keys = Keys(args.robot)
    names = _demo_names(watch, keys, scene, kept)
    if args.swap:
        skill = start_skill(scene)
        stack.enter_context(Child("sctd.cli.main", "run", "--skill", skill, "--robot",
                                  args.robot, *args.child_zenoh, log=logdir / "run.log"))
        print(f"sctd teach: daemon started on the shipped {skill!r} (log "
              f"{logdir / 'run.log'}); the arm is the daemon's from now on", flush=True)
    req: dict[str, Any] = {"task": scene, "method": args.then_learn, "demos": names, "swap": args.swap}
    frames = candidate_frames(find_task(scene)) if args.then_learn == "linear" else []
    if frames:
        req["frames"] = frames
    print(f"sctd teach: training {args.then_learn} on {len(names)} demonstrations, then "
          f"at most {args.check_trials} lockstep trials{' and the swap' if args.swap else ''}", flush=True)
    got = client.query(s, keys.learner, codec.pack(req), timeout=900, find=10)
    if got is None or not got[0]:
        raise LoopError(f"the learner did not train: {got[1].get('error') if got else 'no reply'}")
    reply = got[1]
    if reply.get("swapped"):
        _wait(lambda: watch.skill == reply["id"], 10)
        reply["last_demo_to_swap_s"] = round(time.monotonic() - t_last, 2)
        time.sleep(0.5)  # targets after the swap, for the gap
    watch.recording = False
    reply["swap_gap_ms"] = watch.max_gap_ms()
    return reply


def print_reply(reply: dict[str, Any]) -> None:
    """The steps of the learner's reply with their times, and the check's table."""
    t = reply.get("timings", {})
    ev = reply.get("evaluation") or {}
    print(f"sctd teach: trained {reply['ref']} in {t.get('train_s', 0):.1f} s", flush=True)
    if ev:
        print(f"sctd teach: checked in {t.get('check_s', 0):.1f} s: {ev.get('successes')}/"
              f"{ev.get('trials')} lockstep trials succeeded", flush=True)
        for row in ev.get("table", []):
            print(f"  {row}")
    print(f"sctd teach: {reply.get('reason')}", flush=True)  # "swapped: ...", "kept the active ..."
    if reply.get("swapped"):
        gap = reply.get("swap_gap_ms")
        print(f"sctd teach: the daemon runs {reply['id']}; from the last demonstration to the "
              f"swapped skill {reply['last_demo_to_swap_s']:.1f} s; largest gap between targets "
              f"across the swap {'-' if gap is None else f'{gap:.2f} ms'}", flush=True)


def evaluate_taught(reply: dict[str, Any], scene: str, method: str, trials: int) -> list[dict[str, Any]]:
    """``sctd eval --lockstep`` of the taught skill and, in the same run, the shipped
    learned skill of the same method where there is one (``<scene>-<method>``): the
    same seeds, the same simulated user. Prints the table; returns the results."""
    shipped = shipped_folder() / f"{scene}-{method}.yaml"
    paths = [reply["path"], *([str(shipped)] if shipped.is_file() else [])]
    labels = [f"taught {reply['ref']}", f"shipped {shipped.stem}"]
    t0 = time.monotonic()
    print(f"sctd teach: evaluating {' and '.join(labels[:len(paths)])}: {trials} lockstep trials "
          "each (seeds from 0, the steady user)", flush=True)
    with tempfile.TemporaryDirectory(prefix="sctd-teach-eval-") as work:
        ents = [replace(e, label=label) for e, label in
                zip(entries(paths, baseline=False, workdir=Path(work)), labels, strict=False)]
        spec = TaskSpec.of(find_task(scene), scene)
        results = evaluate(ents, spec, trials, 0, jobs=2, logdir=Path(work) / "logs")
    for row in table(results):
        print(f"  {row}")
    print(f"sctd teach: evaluated in {time.monotonic() - t0:.0f} s", flush=True)
    return results
