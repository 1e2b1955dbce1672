"""The teaching session: demonstrations planned, shown on the arm, recorded, judged.

Per attempt (:func:`teach`):

1. move, unrecorded, to the planned start (:mod:`.plan`: the seeded variation);
2. reset the scene (``sim/reset``: the bottle full, the drawer closed);
3. record (:class:`~sctd_services.record.Take`) the task motion: pour, the carry through
   the via point and the pour, until the scene says the fill target is reached (or a
   drop is spilled); drawer, the reach to the handle (grasped on arrival) and the pull;
4. stop recording, finish unrecorded (pour: the bottle back upright about its opening,
   so the last drops land where the stream did) and judge from the scene's outcome: a
   pour must reach the fill target without a drop spilled, once the bottle is upright
   (the evaluation judges a pour once it stops pouring, too); a drawer must be open to
   the success opening while still held;
5. keep it (``demo_NNN.csv``, published on ``sctd/<robot>/demos/<task>/<name>``) or
   discard it, saying why; the drawer's handle is let go by resetting the scene (the
   simulated hand has no gripper to open, and pulling it off would take more than the
   arm's guard admits).

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
from sctd.wire import DEFAULT_ROBOT

from ..record import Recorder, Take
from .motion import Motion, move, task_motions, upright
from .plan import TASK_OBJECT, DemoPlan, SceneGeometry, Speeds, Variation, plan_demonstration, scene_geometry
from .stream import SimulatorLost, StreamLimits, Teacher, TeachingError, WrongScene

Array = NDArray[np.float64]
COMMANDER_WINDOW = 1.0  # s of listening for another commander's status before the first target
POUR_TIMEOUT = 15.0  # s the tilted bottle may take to fill the mug


def _option(default: Any, help: str, **meta: Any) -> Any:
    return field(default=default, metadata={"help": help, **meta})


@dataclass(frozen=True)
class TeachOptions:
    """A teaching session. Each documented field is a ``sctd teach`` flag of the same name."""

    scene: str = _option("pour", "the task to demonstrate (the simulator's scene)",
                         choices=("pour", "drawer"))
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
                                            "makes a mistake (pour: the opening 6 cm off the mug's "
                                            "axis, it spills; drawer: the hand 5 cm beside the "
                                            "handle, it never grasps), to see one discarded",
                                        metavar="N")

    def __post_init__(self) -> None:
        problems = [(self.demos >= 1, "--demos: must be >= 1"),
                    (self.max_attempts is None or self.max_attempts >= 1, "--max-attempts: must be >= 1"),
                    (self.record_rate > 0, "--record-rate: must be > 0"),
                    (self.wait > 0, "--wait: must be > 0"),
                    (all(n >= 1 for n in self.mistakes), "--mistake: attempt numbers start at 1"),
                    (self.scene in TASK_OBJECT, f"--scene: one of {', '.join(TASK_OBJECT)}")]
        for ok, problem in problems:
            if not ok:
                raise ValueError(problem)

    @property
    def out_dir(self) -> Path:
        return Path(self.out) if self.out else Path("demos") / f"{self.scene}-taught"

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
          on_attempt: Callable[[Attempt], None] | None = None, variation: Variation | None = None,
          speeds: Speeds | None = None, limits: StreamLimits | None = None) -> list[Attempt]:
    """Teach ``options.demos`` demonstrations of ``options.scene`` on the simulator that
    ``session`` reaches; the kept attempts, in order (fewer when ``max_attempts`` ran
    out). ``on_attempt`` hears of every attempt as it ends.

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
    geometry = scene_geometry(options.scene)
    variation, speeds = variation or Variation(), speeds or Speeds()
    out = options.out_dir
    kept: list[Attempt] = []
    with Recorder(session, options.robot, TASK_OBJECT[options.scene], task=options.scene) as rec, \
            Teacher(session, rec, limits or StreamLimits()) as teacher:
        _wait_for_simulator(teacher, rec, options)
        out.mkdir(parents=True, exist_ok=True)
        for n in range(1, options.attempts + 1):
            if len(kept) >= options.demos:
                break
            plan = plan_demonstration(geometry, options.seed, n, variation, n in options.mistakes)
            attempt = _attempt(teacher, rec, plan, geometry, out, options, speeds)
            if on_attempt is not None:
                on_attempt(attempt)
            if attempt.kept:
                kept.append(attempt)
    return kept


def _wait_for_simulator(teacher: Teacher, rec: Recorder, options: TeachOptions) -> None:
    """Wait for the simulator's state, task object and scene (refusing one that runs
    another scene as soon as it says so), and listen COMMANDER_WINDOW s longer for
    another commander (its status is 20 Hz by default)."""
    give_up = time.monotonic() + options.wait
    while rec.sample() is None or rec.scene is None:
        teacher.check_commander()
        _check_scene(rec, options)
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
    """WrongScene when the simulator announces another scene than ``options.scene``."""
    running = rec.scene.get("scene") if rec.scene is not None else None
    if running is not None and running != options.scene:
        raise WrongScene(f"the simulator on sctd/{options.robot} runs scene {running!r}, not "
                         f"{options.scene!r}")


def _attempt(teacher: Teacher, rec: Recorder, plan: DemoPlan, geometry: SceneGeometry, out: Path,
             options: TeachOptions, speeds: Speeds) -> Attempt:
    """One attempt: to the start, reset, record, judge, keep or discard."""
    t0 = time.monotonic()
    attempt = Attempt(plan.attempt, plan)
    try:
        T_world_obj = teacher.object_pose()
        _move_to(teacher, plan.T_obj_start, T_world_obj, speeds)
        teacher.reset_scene(options.scene)
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
    attempt.elapsed = time.monotonic() - t0
    return attempt


def _leave(teacher: Teacher, plan: DemoPlan, geometry: SceneGeometry, options: TeachOptions,
           speeds: Speeds) -> None:
    """After an attempt, unrecorded: the bottle upright about its opening if it is still
    tilted (an attempt that ended early); the drawer's handle let go by resetting the
    scene (see the module doc)."""
    if plan.task == "drawer":
        teacher.reset_scene(options.scene)
        return
    T_world_obj = teacher.object_pose()
    T_obj_ee = se3.invert_transform(T_world_obj) @ teacher.target()
    back = upright(T_obj_ee, geometry, speeds)
    if back.angle > 0.05:
        teacher.phase = "upright"
        teacher.follow(back, T_world_obj)


def _record(teacher: Teacher, take: Take, attempt: Attempt, geometry: SceneGeometry,
            T_world_obj: Array, speeds: Speeds) -> None:
    """Record the task motion into ``take`` (stopped on return), finish it unrecorded
    and judge it: fills ``attempt``'s rows, duration, outcome and reason."""
    plan = attempt.plan
    take.start()
    try:
        if not teacher.hold(lambda: len(take.rows) > 0, 2.0):  # the take has its first row
            raise TeachingError("the recorder took no sample within 2 s")
        first, second = task_motions(plan, geometry, speeds)
        teacher.phase = "carry" if plan.task == "pour" else "reach"
        teacher.follow(first, T_world_obj)
        teacher.phase = "pour" if plan.task == "pour" else "pull"
        if plan.task == "pour":
            _pour(teacher, second, T_world_obj)
        else:
            teacher.follow(second, T_world_obj)
    finally:
        attempt.rows = take.stop()
        attempt.duration = take.rows[-1][0] if take.rows else 0.0
    if plan.task == "pour":
        teacher.phase = "upright"
        T_obj_ee = se3.invert_transform(T_world_obj) @ teacher.target()
        teacher.follow(upright(T_obj_ee, geometry, speeds), T_world_obj)
    teacher.settle()
    attempt.outcome = teacher.scene_after(time.time())
    attempt.reason = judge(attempt.outcome)


def _pour(teacher: Teacher, turn: Motion, T_world_obj: Array) -> None:
    """Tilt the bottle (``turn``) and hold it until the fill target is reached or a drop
    spilled (a person stops pouring then); TeachingError when neither comes in time."""
    def enough() -> bool:
        sc = teacher.rec.scene or {}
        return bool(sc.get("spilled")) or float(sc.get("poured", 0.0)) >= float(
            sc.get("fill_target", 0.5))
    if not teacher.follow(turn, T_world_obj, stop_when=enough):
        return
    if not teacher.hold(enough, POUR_TIMEOUT):
        sc = teacher.rec.scene or {}
        raise TeachingError(f"the fill target was not reached in {POUR_TIMEOUT:g} s of pouring "
                            f"(poured {float(sc.get('poured', 0.0)):.2f})")


def _move_to(teacher: Teacher, T_obj_goal: Array, T_world_obj: Array, speeds: Speeds) -> None:
    """The unrecorded move from where the hand is (its last target) to ``T_obj_goal``."""
    teacher.phase = "move"
    T_obj_from = se3.invert_transform(T_world_obj) @ teacher.target()
    teacher.follow(move(T_obj_from, T_obj_goal, speeds), T_world_obj)
    teacher.settle()


def judge(outcome: dict) -> str:
    """Why the scene's ``outcome`` (a scene message) is no successful demonstration, or
    "" when it is: the scene's own ``success`` (pour: the fill target reached, nothing
    spilled; drawer: open to the success opening)."""
    if outcome.get("success") is True and not outcome.get("spilled"):
        return ""
    if outcome.get("scene") == "pour":
        if outcome.get("spilled"):
            return (f"spilled {float(outcome.get('spilled_amount', 0.0)):.3f} of the bottle "
                    f"(poured {float(outcome.get('poured', 0.0)):.2f})")
        return (f"poured {float(outcome.get('poured', 0.0)):.2f}, short of the fill target "
                f"{float(outcome.get('fill_target', 0.5)):.2f}")
    opening = float(outcome.get("opening", 0.0))
    needed = float(outcome.get("target_opening", 0.2))
    text = f"the drawer opened {opening:.3f} m of the {needed:.2f} m needed"
    if not outcome.get("grasps"):
        text += "; the hand never grasped the handle"
    return text


def describe_outcome(outcome: dict) -> str:
    """The outcome in a few words (pour: poured and spilled; drawer: the opening)."""
    if outcome.get("scene") == "pour":
        return (f"poured {float(outcome.get('poured', 0.0)):.2f}, spilled "
                f"{float(outcome.get('spilled_amount', 0.0)):.3f}")
    if outcome.get("scene") == "drawer":
        return f"opened {float(outcome.get('opening', 0.0)):.3f} m"
    return ""


