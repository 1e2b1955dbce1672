"""The daemon's side of a skill swap: the skill server it starts, and each validated
skill swapped into the tick between two ticks.

The skill queryables are served by a child process, the skill server
(:mod:`.skillserver`), so that no bundle's bytes are ever in the daemon's process: it
receives, validates and hands over each swapped-in skill (its model arrays read without
long GIL holds). :class:`SkillSwap` compiles it here on a thread of its own (KD-trees
release the GIL), hands it to the tick through a one-slot mailbox (:attr:`~SkillSwap.pending`,
one attribute read per tick) and the tick thread installs it between two ticks
(:meth:`~SkillSwap.install`); the replaced skill is freed on the swapping thread too, and
the query is answered once the swap landed. Each step that holds the GIL for a while
begins just after a tick (:meth:`~SkillSwap.between_ticks`), with most of a period ahead
of it.

When the daemon runs a skill set (:mod:`.goals`), a swap replaces one member
(:func:`.sets.check_swap`: the member the request names, else the member of the new
skill's name), with the object rings of the set's objects after it, and the summary is
the running skill's with the set's own (``set``).
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from ..skill import Skill, SkillEngine, SkillError, skill_summary
from ..timing import Ticker
from .driver import TickDriver
from .ingress import Ingress, Inlet
from .sets import check_swap, set_summary
from .skillserver import ServerOptions, SkillServer
from .worker import WHERE

log = logging.getLogger("sctd.run")
SERVER_WAIT = 20.0  # s the start waits for the skill server to serve the skill queryables
# How long after a deadline the tick has published its target and sleeps until the next
# drain: a swap's longer GIL holds start then, with most of a period ahead of them.
AFTER_TICK = 3e-4
BOUNDARY_WAIT = 5.0  # s a swap waits for the tick to install it


@dataclass
class _Pending:
    """A compiled skill on its way into the tick, and what the swap learns back."""

    skill: Skill
    engine: SkillEngine
    objects: dict[str, Inlet]
    done: threading.Event
    state: str = ""
    retired: list[Inlet] = field(default_factory=list)  # object rings the new skill does not use
    replaced: tuple[Skill, SkillEngine] | None = None  # freed off the tick thread
    member: str | None = None  # a skill set's member the skill replaces


class SkillSwap:
    """The skill queryables' daemon side: answers the skill server (summaries, swaps,
    refusals counted) and swaps skills into ``driver`` between two ticks (module doc).

    Parameters
    ----------
    driver : TickDriver
        The tick's driver, whose skill (or skill set's member) is swapped.
    stop_event : threading.Event, optional
        Set when the daemon stops: a swap is refused from then on, one under way fails
        its wait, and a skill server that dies is not replaced.
    set_name : str
        The skill set's name, when the driver runs one (the summary's ``set.name``).

    Attributes
    ----------
    pending : _Pending or None
        The one-slot mailbox the tick reads.
    ingress : Ingress or None
        The running loop's rings (set once they exist): a swap opens the new skill's
        object rings there; None while not running (a swap is refused).
    ticker : Ticker or None
        The running loop's ticker, by which a swap times its steps.
    refused : int
        Refusals of the skill queryables, whatever their cause.
    """

    def __init__(self, driver: TickDriver, stop_event: threading.Event | None = None, set_name: str = ""):
        self.driver = driver
        self.set_name = set_name
        self.stop_event = stop_event if stop_event is not None else threading.Event()
        self.pending: _Pending | None = None
        self.ingress: Ingress | None = None
        self.ticker: Ticker | None = None
        self.refused = 0
        self.server: SkillServer | None = None
        self._lock = threading.Lock()  # the mailbox
        self._swap_lock = threading.Lock()  # one swap at a time

    def serve(self, options: ServerOptions, rt_priority: int = 0) -> SkillServer:
        """The skill server that answers with this swap; a context manager that starts it
        (:class:`~.skillserver.SkillServer`)."""
        self.server = SkillServer(options, self.summary, self.answer, self.refuse, self.stop_event,
                                  self.between_ticks, rt_priority)
        return self.server

    def wait_served(self, timeout: float = SERVER_WAIT) -> None:
        """Until the skill server serves the skill queryables, a stop is asked for, or
        ``timeout`` s have passed (then the loop ticks without them for now)."""
        assert self.server is not None
        give_up = time.monotonic() + timeout
        while not self.server.wait_ready(0.05) and not self.stop_event.is_set():
            if time.monotonic() > give_up:
                log.warning("the skill queryables are not served yet (%g s); ticking anyway", timeout)
                return

    # --- the skill server's threads ------------------------------------------------------

    def summary(self) -> dict[str, Any]:
        """The active skill's summary and FSM state (the ``skill`` queryable's answer);
        with a skill set, the running skill's (teleoperation's while no member is
        engaged) and the set's (``set``)."""
        summary = skill_summary(self.driver.skill)
        summary["state"] = self.driver.engine.state
        goals = self.driver.goals
        if goals is not None:
            summary["set"] = set_summary(self.set_name, goals)
        return summary

    def in_use(self) -> list[str]:
        """The ids of the skills the daemon may run without a swap: the running one and,
        with a set, its members' and teleoperation's (their bundles are all kept)."""
        goals = self.driver.goals
        ids = [self.driver.skill.id]
        if goals is not None:
            ids += [goals.teleop.id, *(m.skill.id for m in goals.members)]
        return list(dict.fromkeys(ids))

    def refuse(self, error: str) -> None:
        """Every refusal of the skill queryables, whatever its cause, is counted."""
        log.warning("refused skill: %s", error)
        self.refused += 1

    def between_ticks(self) -> None:
        """Return just after the next tick has published its target, when the tick thread
        sleeps for most of a period: the swap's steps that hold the GIL for a while
        (unpickling the skill, a KD-tree build's start, freeing the replaced skill) begin
        there, so that they end before the tick wakes again. At once when not ticking."""
        ticker = self.ticker
        if ticker is None or self.stop_event.is_set():
            return
        wait = ticker.due + AFTER_TICK - time.monotonic()
        if wait > 0.0:
            time.sleep(min(wait, ticker.period + AFTER_TICK))

    def answer(self, skill: Skill, member: str | None = None) -> dict[str, Any]:
        """A swap asked for through the skill server (:meth:`swap`): the FSM state it
        landed in and, with a skill set, the member it replaced and the ids of the set's
        skills after it (:meth:`in_use`: their bundles stay kept)."""
        state, replaced = self._swap(skill, member)
        out: dict[str, Any] = {"state": state}
        if replaced is not None:
            out["member"], out["in_use"] = replaced, self.in_use()
        return out

    def swap(self, skill: Skill, member: str | None = None) -> str:
        """Install a validated skill at a tick boundary: its engine (KD-trees release the
        GIL) and object rings are made here, off the tick thread, and so is the replaced
        skill freed, each step begun between two ticks. With a skill set it replaces
        ``member`` (default: the member of its name; :func:`.sets.check_swap`). Returns
        the FSM state the swap landed in (a member that is not engaged: the state the
        new skill starts from when it engages).

        Raises
        ------
        SkillError
            The daemon is not running, did not reach a tick boundary in
            :data:`BOUNDARY_WAIT` s, or the swap does not fit the set (or names a
            member of a daemon that runs none).
        """
        return self._swap(skill, member)[0]

    def _swap(self, skill: Skill, member: str | None) -> tuple[str, str | None]:
        """:meth:`swap`; also the member replaced (None: the skill)."""
        with self._swap_lock:
            ingress = self.ingress
            if ingress is None or self.stop_event.is_set():
                raise SkillError(WHERE, "", "the daemon is not running")
            goals = self.driver.goals
            if goals is not None:
                member = check_swap(goals, skill, member)
                names = [*skill.objects(), *(o for m in goals.members if m.name != member
                                             for o in m.skill.objects())]
            elif member is not None:
                raise SkillError(WHERE, "", f"member {member!r}: the daemon runs one skill, not a skill "
                                            "set: swap without naming a member")
            else:
                names = list(skill.objects())
            self.between_ticks()
            engine = SkillEngine(skill)
            self.between_ticks()
            objects = ingress.object_inlets(names)
            pending = _Pending(skill, engine, objects, threading.Event(), member=member)
            with self._lock:
                self.pending = pending
            if not self._landed(pending):
                self._withdraw(pending, ingress)
                raise SkillError(WHERE, "", "the daemon stopped or did not reach a tick boundary "
                                            f"in {BOUNDARY_WAIT:g} s")
            self.between_ticks()
            for inlet in pending.retired:  # the tick no longer drains these
                inlet.close()
            pending.replaced = None
        log.info("swapped to skill %s@%s (state %s)%s", skill.name, skill.id, pending.state,
                 "" if member is None else f" in the place of member {member}")
        return pending.state, member

    def _landed(self, pending: _Pending) -> bool:
        """Wait until the tick installed ``pending``, the daemon stops, or
        :data:`BOUNDARY_WAIT` s pass; whether it was installed."""
        deadline = time.monotonic() + BOUNDARY_WAIT
        while not pending.done.wait(0.05) and time.monotonic() < deadline \
                and not self.stop_event.is_set():
            pass
        return pending.done.is_set()

    def _withdraw(self, pending: _Pending, ingress: Ingress) -> None:
        """A swap that did not land: out of the mailbox, its new object rings closed."""
        with self._lock:
            if self.pending is pending:
                self.pending = None
        for name, inlet in pending.objects.items():
            if ingress.objects.get(name) is not inlet:
                inlet.close()

    # --- the tick thread -----------------------------------------------------------------

    def install(self, now: float) -> None:
        """On the tick thread, between two ticks (``now``: monotonic), when
        :attr:`pending` is set: the new skill and its object rings. The replaced skill and
        engine are kept for the swapping thread to free."""
        with self._lock:
            pending, self.pending = self.pending, None
        if pending is None:  # withdrawn meanwhile
            return
        driver = self.driver
        if pending.member is None:
            pending.replaced = (driver.skill, driver.engine)
            driver.swap(pending.skill, now, pending.engine)
        else:
            goals = driver.goals
            assert goals is not None
            i = goals.index(pending.member)
            pending.replaced = (goals.members[i].skill, goals.engines[i])
            driver.swap_member(pending.member, pending.skill, now, pending.engine)
        assert self.ingress is not None
        pending.retired = self.ingress.use_objects(pending.objects)
        pending.state = driver.engine.state if driver.skill is pending.skill else pending.skill.start
        pending.done.set()
