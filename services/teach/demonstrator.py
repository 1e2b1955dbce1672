"""The teaching session: demonstrations planned, shown on the arm, recorded, judged.

Per attempt (:func:`teach`):

1. move, unrecorded, to the planned start (:mod:`.plan`: the seeded variation);
2. reset the scene (``sim/reset``: a bottle full, a drawer closed);
3. record (:class:`~sctd_services.record.Take`) the task motion, one motion per step of
   the task's intent (:mod:`.motion`): a reach (a handle is grasped on arrival), a tilt
   held until its predicate holds (the fill target reached), a joint moved, a button
   pushed in, held until its predicate holds (the light on) and let out; a step ends
   early when one of the task's failure rules holds (a drop spilled, a switch pushed too
   hard);
4. stop recording, finish unrecorded (the intent's last uprights: a bottle back upright
   about its opening, so the last drops land where the stream did), hold still until the
   task is done or has failed (a frame held in a zone for its time; at most
   ``DONE_TIMEOUT`` s) and judge from the scene's outcome: the task done and successful,
   no failure rule holding (the evaluation judges a pour once it stops pouring, too);
5. keep it (``demo_NNN.csv``, published on ``sctd/<robot>/demos/<task>/<name>``) or
   discard it, saying why; a grasped handle is let go by resetting the scene (the
   simulated hand has no gripper to open, and pulling it off would take more than the
   arm's guard admits); a hand left pressing a surface is pulled back off it.

Until ``demos`` are kept or ``max_attempts`` made. An attempt the arm cannot follow
(a start out of its reach) is discarded like a failed one; a lost simulator or another
commander ends the session.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import zenoh
from numpy.typing import NDArray

from sctd import se3
from sctd.task import Task, TaskError, find_task
from sctd.task.judge import holds, thresholds
from sctd.task.model import AllOf, AnyOf, Compare, Not, Predicate
from sctd.wire import DEFAULT_ROBOT

from ..record import Recorder, Take
from .motion import LegsMotion, Motion, PressMotion, move, task_motions, upright
from .plan import (
    PRESS_STANDOFF,
    DemoPlan,
    SceneGeometry,
    Speeds,
    StepPlan,
    plan_demonstration,
    scene_geometry,
)
from .stream import SimulatorLost, StreamLimits, Teacher, TeachingError, WrongScene

Array = NDArray[np.float64]
COMMANDER_WINDOW = 1.0  # s of listening for another commander's status before the first target
GRASP_WAIT = 3.0  # s at most a hand at a handle waits to close on it before it pulls
TILT_TIMEOUT = 15.0  # s a tilt may be held for its predicate (the tilted bottle to fill the mug)
PRESS_TIMEOUT = 5.0  # s a pushed button may be held for its predicate (the light to come on)
DONE_TIMEOUT = 10.0  # s the finished hand is held still for the task to be done (a dwell in a zone)


def _option(default: Any, help: str, **meta: Any) -> Any:
    return field(default=default, metadata={"help": help, **meta})


@dataclass(frozen=True)
class TeachOptions:
    """A teaching session. Each documented field is a ``sctd teach`` flag of the same name."""

    task: str = _option("", "the task to demonstrate: a name sctd tasks lists, or a task file "
                            "(the simulator's scene)", metavar="NAME|FILE")
    demos: int = _option(10, "demonstrations to keep")
    out: str = _option("", "folder the kept demonstrations go to, as demo_NNN.csv after any "
                           "already there (default demos/<scene>-taught)", metavar="DIR")
    seed: int = _option(0, "seed of the variations: the same seed shows the same demonstrations")
    robot: str = _option(DEFAULT_ROBOT, "key prefix sctd/<robot>")
    max_attempts: int | None = _option(None, "give up after this many attempts (default twice "
                                             "--demos, at least 3)", metavar="N")
    record_rate: float = _option(100.0, "recording rate, Hz (as sctd record's --rate)")
    wait: float = _option(60.0, "s to wait for the simulator's first state, object and scene")
    mistakes: tuple[int, ...] = _option((), "attempt numbers (from 1) in which the demonstrator "
                                            "makes a mistake (every reach misses its goal by the "
                                            "task's miss: a bottle's opening beside the mug, it "
                                            "spills; a hand beside a handle, it never grasps), to "
                                            "see one discarded",
                                        metavar="N", flag="--mistake", repeatable=True)

    def __post_init__(self) -> None:
        problems = [(self.demos >= 1, "--demos: must be >= 1"),
                    (self.max_attempts is None or self.max_attempts >= 1, "--max-attempts: must be >= 1"),
                    (self.record_rate > 0, "--record-rate: must be > 0"),
                    (self.wait > 0, "--wait: must be > 0"),
                    (all(n >= 1 for n in self.mistakes), "--mistake: attempt numbers start at 1"),
                    (bool(self.task), "--task: a task is needed")]
        for ok, problem in problems:
            if not ok:
                raise ValueError(problem)
        try:
            object.__setattr__(self, "_task", find_task(self.task))
        except TaskError as e:
            raise ValueError(f"--task: {e}") from None

    @property
    def the_task(self) -> Task:
        """The task ``task`` names (read when the options were made)."""
        return self.__dict__["_task"]

    @property
    def name(self) -> str:
        """The task's name (a file's ``name`` field): its demonstrations' key and the
        simulator's scene."""
        return self.the_task.name

    @property
    def out_dir(self) -> Path:
        return Path(self.out) if self.out else Path("demos") / f"{self.name}-taught"

    @property
    def attempts(self) -> int:
        return self.max_attempts or max(3, 2 * self.demos)


@dataclass
class Attempt:
    """What one attempt came to.

    Attributes
    ----------
    number : int
        From 1.
    plan : DemoPlan
    kept : bool
    reason : str
        Why it was discarded ("" when kept).
    outcome : dict
        The scene's message it was judged on (empty when it ended before).
    rows : int
        Rows recorded.
    duration : float
        s recorded (the last row's ``t``).
    elapsed : float
        s the attempt took, its unrecorded moves included.
    path : Path or None
        The kept file.
    key : str or None
        The key it was published on.
    """

    number: int
    plan: DemoPlan
    kept: bool = False
    reason: str = ""
    outcome: dict = field(default_factory=dict)
    rows: int = 0
    duration: float = 0.0
    elapsed: float = 0.0
    path: Path | None = None
    key: str | None = None

    @property
    def name(self) -> str:
        return self.path.stem if self.path is not None else "-"


def teach(session: zenoh.Session, options: TeachOptions,
          on_attempt: Callable[[Attempt], None] | None = None, speeds: Speeds | None = None,
          limits: StreamLimits | None = None, gone: Callable[[], str | None] | None = None
          ) -> list[Attempt]:
    """Teach ``options.demos`` demonstrations of ``options.task`` on the simulator that
    ``session`` reaches; the kept attempts, in order (fewer when ``max_attempts`` ran
    out). ``on_attempt`` hears of every attempt as it ends. ``gone``, where the caller
    started the simulator: why it is no more (its exit and its own error), or None while
    it runs; waiting for it ends at once when it is gone.

    The caller keeps the session open a moment after this returns, so that the last
    demonstration published leaves the process (``sctd_services.record.LINGER``).

    Raises
    ------
    CommanderConflict
        A shared-control daemon commands the robot (before the first target or later;
        from then on no target is published).
    SimulatorLost
        No simulator within ``options.wait``, or its state stopped.
    WrongScene
        The simulator runs another scene.
    """
    task = options.the_task
    geometry = scene_geometry(task)
    speeds = speeds or Speeds()
    out = options.out_dir
    kept: list[Attempt] = []
    with Recorder(session, options.robot, task.object, task=task.name) as rec, \
            Teacher(session, rec, limits or StreamLimits()) as teacher:
        _wait_for_simulator(teacher, rec, options, gone)
        out.mkdir(parents=True, exist_ok=True)
        for n in range(1, options.attempts + 1):
            if len(kept) >= options.demos:
                break
            plan = plan_demonstration(geometry, options.seed, n, n in options.mistakes)
            attempt = _attempt(teacher, rec, plan, geometry, out, options, speeds)
            if on_attempt is not None:
                on_attempt(attempt)
            if attempt.kept:
                kept.append(attempt)
    return kept


def _wait_for_simulator(teacher: Teacher, rec: Recorder, options: TeachOptions,
                        gone: Callable[[], str | None] | None = None) -> None:
    """Wait for the simulator's state, task object and scene (refusing one that runs
    another scene as soon as it says so, giving up as soon as ``gone`` says why it is
    no more), and listen COMMANDER_WINDOW s longer for another commander (its status is
    20 Hz by default)."""
    give_up = time.monotonic() + options.wait
    while rec.sample() is None or rec.scene is None:
        teacher.check_commander()
        _check_scene(rec, options)
        why = gone() if gone is not None else None
        if why is not None:
            raise SimulatorLost(why)
        if time.monotonic() > give_up:
            what = "state" if rec.state is None else "scene" if rec.scene is None else \
                f"object {rec.object_name}"
            raise SimulatorLost(f"no simulator on sctd/{options.robot}: no {what} within "
                                f"{options.wait:g} s")
        time.sleep(0.02)
    _check_scene(rec, options)
    end = time.monotonic() + COMMANDER_WINDOW
    while time.monotonic() < end:
        teacher.check_commander()
        time.sleep(0.02)
    teacher.check_commander()


def _check_scene(rec: Recorder, options: TeachOptions) -> None:
    """WrongScene when the simulator announces another scene than ``options.task``'s."""
    running = rec.scene.get("scene") if rec.scene is not None else None
    if running is not None and running != options.name:
        raise WrongScene(f"the simulator on sctd/{options.robot} runs scene {running!r}, not "
                         f"{options.name!r}")


def _attempt(teacher: Teacher, rec: Recorder, plan: DemoPlan, geometry: SceneGeometry, out: Path,
             options: TeachOptions, speeds: Speeds) -> Attempt:
    """One attempt: to the start, reset, record, judge, keep or discard."""
    t0 = time.monotonic()
    attempt = Attempt(plan.attempt, plan)
    try:
        if _moves_things(geometry.task):  # (the task object where it starts, not where it was left)
            teacher.reset_scene(options.name)
            teacher.scene_after(time.time())
            teacher.scene_after(time.time())  # (an object message after the reset's has come)
        T_world_obj = teacher.object_pose()
        _move_to(teacher, plan.T_obj_start, T_world_obj, speeds)
        teacher.reset_scene(options.name)
        teacher.scene_after(time.time())  # from now on the scene shows the reset state
        with Take(rec, out, options.record_rate) as take:
            _record(teacher, take, attempt, geometry, T_world_obj, speeds)
            if not attempt.reason:
                take.keep()
                attempt.kept, attempt.path, attempt.key = take.path is not None, take.path, take.key
                if take.path is None:
                    attempt.reason = f"only {attempt.rows} rows recorded"
    except (SimulatorLost, WrongScene):
        raise
    except TeachingError as e:
        attempt.reason = attempt.reason or str(e)
    finally:
        with contextlib.suppress(TeachingError):  # whatever happened: leave the task
            _leave(teacher, plan, geometry, options, speeds)
        # An arm that could not follow (a joint at its limit, the hand against something)
        # is put back at rest in its start posture, a known one, and the next attempt's
        # move starts from there (it failed at once, every attempt after the first that
        # got stuck, chasing the stuck target)
        if teacher.reseed_if_behind():
            with contextlib.suppress(TeachingError):
                teacher.reset_scene(options.name, home=True)
    attempt.elapsed = time.monotonic() - t0
    return attempt


def _leave(teacher: Teacher, plan: DemoPlan, geometry: SceneGeometry, options: TeachOptions,
           speeds: Speeds) -> None:
    """After an attempt, unrecorded: a grasped handle let go by resetting the scene (see
    the module doc); else a tilted frame brought upright about its point if it is still
    tilted (an attempt that ended early)."""
    task = geometry.task
    if task.scene.joints or _moves_things(task):
        teacher.reset_scene(options.name)
        return
    presses = [s for s in plan.steps if s.kind == "press"]
    if presses:
        _pull_back(teacher, geometry, presses[-1], speeds)
        return
    tilts = [s for s in plan.steps if s.kind == "tilt"]
    if not tilts:
        return
    T_world_obj = teacher.object_pose()
    T_obj_ee = se3.invert_transform(T_world_obj) @ teacher.target()
    back = upright(T_obj_ee, geometry.frame(tilts[-1].frame)[:3, 3], speeds)
    if back.angle > 0.05:
        teacher.phase = "upright"
        teacher.follow(back, T_world_obj)


def _moves_things(task: Task) -> bool:
    """Whether the task's hand takes things (an item, a knob): an attempt leaves them
    moved or held, so the scene is reset after it and before the next."""
    return any(f.physics(n, task.scene) is not None for n, b in task.scene.bodies.items()
               for f in b.facets.values())


def _pull_back(teacher: Teacher, geometry: SceneGeometry, press: StepPlan, speeds: Speeds) -> None:
    """The hand moved out along the button's outward normal by the press's standoff,
    from where it is (off the wall, if an attempt ended pressing it)."""
    T_world_obj = teacher.object_pose()
    T_obj_ee = se3.invert_transform(T_world_obj) @ teacher.target()
    T_out = T_obj_ee.copy()
    T_out[:3, 3] += PRESS_STANDOFF * geometry.body(press.button)[:3, 0]
    teacher.phase = "move"
    teacher.follow(move(T_obj_ee, T_out, speeds), T_world_obj)


def _record(teacher: Teacher, take: Take, attempt: Attempt, geometry: SceneGeometry,
            T_world_obj: Array, speeds: Speeds) -> None:
    """Record the task motion into ``take`` (stopped on return), finish it unrecorded
    and judge it: fills ``attempt``'s rows, duration, outcome and reason."""
    task = geometry.task
    motions = task_motions(attempt.plan, geometry)
    recorded = geometry.recorded
    take.start()
    try:
        if not teacher.hold(lambda: len(take.rows) > 0, 2.0):  # the take has its first row
            raise TeachingError("the recorder took no sample within 2 s")
        for step, motion in motions[:recorded]:
            if not _show(teacher, task, step, motion, T_world_obj):
                break  # a failure rule holds: nothing more to show
    finally:
        attempt.rows = take.stop()
        attempt.duration = take.rows[-1][0] if take.rows else 0.0
    for step, _ in motions[recorded:]:  # the finish (uprights), from where the hand is
        teacher.phase = step.name
        T_obj_ee = se3.invert_transform(T_world_obj) @ teacher.target()
        teacher.follow(upright(T_obj_ee, geometry.frame(step.frame)[:3, 3], speeds), T_world_obj)
    teacher.settle()
    # a person who has shown every step stays still until the task is over (the cup held
    # at the lips for its time), or it has failed, for at most DONE_TIMEOUT s
    failed = _failing(teacher, task)
    teacher.hold(lambda: failed() or bool((teacher.rec.scene or {}).get("done")), DONE_TIMEOUT)
    attempt.outcome = teacher.scene_after(time.time())
    attempt.reason = judge(attempt.outcome, task)


def _show(teacher: Teacher, task: Task, step: StepPlan, motion: Motion, T_world_obj: Array) -> bool:
    """Show one step as its plan says: a kind's legs, a press, or a motion, after waiting
    for the hand to hold what the plan names (``grasped``) and followed by holding still
    until the plan's ``until`` holds (TeachingError when it does not in TILT_TIMEOUT s);
    stopped when a failure rule holds (False then)."""
    teacher.phase = step.name
    failed = _failing(teacher, task)
    if isinstance(motion, LegsMotion):
        return _legs(teacher, step, motion, T_world_obj, failed)
    if isinstance(motion, PressMotion):
        return _press(teacher, step, motion, T_world_obj, failed)
    if step.grasped:
        # a person at the handle waits until the hand has closed on it before pulling:
        # an arm still behind the reach's end (a loaded host) would turn away short of
        # the grasp radius. A hand beside the handle (a mistake) stops once it is still.
        held = step.grasped
        teacher.hold(lambda: bool(_readings(teacher).get(held)) or teacher.settled(), GRASP_WAIT)
    until = step.until
    if until is None:
        teacher.follow(motion, T_world_obj, stop_when=failed)
        return not failed()

    def enough() -> bool:
        return failed() or holds(until, _readings(teacher), {})
    if teacher.follow(motion, T_world_obj, stop_when=enough) and not teacher.hold(enough, TILT_TIMEOUT):
        raise TeachingError(f"{step.name}: {_explain(_readings(teacher), until)} not reached in "
                            f"{TILT_TIMEOUT:g} s of holding the tilt")
    return not failed()


def _press(teacher: Teacher, step: StepPlan, motion: PressMotion, T_world_obj: Array,
           failed: Callable[[], bool]) -> bool:
    """Show a press: in to the planned depth, held until the step's predicate holds
    (TeachingError when it does not in PRESS_TIMEOUT s), out again; stopped when a
    failure rule holds (False then)."""
    if not teacher.follow(motion.inward, T_world_obj, stop_when=failed):
        return False
    until = step.until
    assert until is not None  # (a press's plan has one)

    def enough() -> bool:
        return failed() or holds(until, _readings(teacher), {})
    if not teacher.hold(enough, PRESS_TIMEOUT):
        raise TeachingError(f"{step.name}: {_explain(_readings(teacher), until)} not reached in "
                            f"{PRESS_TIMEOUT:g} s of holding the button pushed in")
    return not failed() and teacher.follow(motion.outward, T_world_obj, stop_when=failed)


def _legs(teacher: Teacher, step: StepPlan, motion: LegsMotion, T_world_obj: Array,
          failed: Callable[[], bool]) -> bool:
    """Show a step of a registered kind leg by leg: the hand along the leg, then the
    fingers as it says, then held still until its reading is what it waits for
    (TeachingError when it is not in GRASP_WAIT s: a grasp beside the item never holds
    it); stopped when a failure rule holds (False then)."""
    for line, leg in motion.legs:
        if not teacher.follow(line, T_world_obj, stop_when=failed):
            return False
        if leg.grip is not None:
            teacher.grip(leg.grip, leg.force)
        if leg.until is not None:
            reading, value = leg.until

            def there(r: str = reading, v: bool = value) -> bool:
                return failed() or _readings(teacher).get(r) is v
            if not teacher.hold(there, GRASP_WAIT):
                raise TeachingError(f"{step.name}: {reading} was not {str(value).lower()} within "
                                    f"{GRASP_WAIT:g} s of the fingers' {leg.grip}")
            if failed():
                return False
    return True


def _readings(teacher: Teacher) -> dict:
    return dict((teacher.rec.scene or {}).get("readings", {}))


def _failing(teacher: Teacher, task: Task) -> Callable[[], bool]:
    """Whether one of the task's failure rules holds on the scene's newest readings."""
    rules = task.outcome.fail
    return lambda: any(holds(r.when, _readings(teacher), {}) for r in rules)


def _move_to(teacher: Teacher, T_obj_goal: Array, T_world_obj: Array, speeds: Speeds) -> None:
    """The unrecorded move from where the hand is (its last target) to ``T_obj_goal``."""
    teacher.phase = "move"
    T_obj_from = se3.invert_transform(T_world_obj) @ teacher.target()
    teacher.follow(move(T_obj_from, T_obj_goal, speeds), T_world_obj)
    teacher.settle()


def judge(outcome: dict, task: Task) -> str:
    """Why the scene's ``outcome`` (a scene message) is no successful demonstration of
    ``task``, or "" when it is: the scene's own ``success`` with no failure rule holding.
    Otherwise the failure rules that hold (their reasons), or what the task's ``done``
    still lacks, with the readings that say so."""
    readings = outcome.get("readings", {})
    failing = [r for r in task.outcome.fail if holds(r.when, readings, {})]
    if outcome.get("success") is True and not failing:
        return ""
    if failing:
        why = "; ".join(f"{r.reason} ({_explain(readings, r.when)})" for r in failing)
    elif outcome.get("done"):
        why = f"done but not successful ({_explain(readings, task.outcome.success)})"
    else:
        why = f"not done: {_explain(readings, task.outcome.done)}"
    never = [j for j in task.scene.joints if not readings.get(f"{j}.grasps")]
    return why + "".join(f"; the hand never grasped the handle of {j}" for j in never)


def describe_outcome(outcome: dict, task: Task) -> str:
    """The outcome in a few words: the readings the task's ``done`` asks to reach."""
    return _explain(outcome.get("readings", {}), task.outcome.done)


def _explain(readings: dict, predicate: Predicate) -> str:
    """The readings a predicate names with their values (and the bound a conjunction
    sets, ``bottle.poured 0.30 of 0.50``)."""
    bounds = thresholds(predicate)
    out = []
    for name in _names(predicate):
        x = readings.get(name)
        if x is None:
            out.append(f"{name} not reported")
        elif isinstance(x, bool):
            out.append(f"{name} {str(x).lower()}")
        else:
            out.append(f"{name} {float(x):.3f}" + (f" of {bounds[name]:g}" if name in bounds else ""))
    return ", ".join(dict.fromkeys(out)) or "nothing to report"


def _names(p: Predicate) -> list[str]:
    """The readings a predicate names, in order."""
    if isinstance(p, Compare):
        return [str(p.reading)]
    if isinstance(p, AllOf | AnyOf):
        return [n for t in p.terms for n in _names(t)]
    if isinstance(p, Not):
        return _names(p.term)
    return []
