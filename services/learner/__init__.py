"""``sctd learner``: the learner service (``docs/learner.md``).

- :mod:`.store`: demonstrations by task and trained skills by content id, on disk;
- :mod:`.request`: the training request, checked field by field;
- :mod:`.check`: the lockstep check before a swap;
- :mod:`.service`: the Zenoh service (demonstrations in, requests answered, status).

``python -m sctd_services.learner`` takes the same flags as ``sctd learner``.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading

from sctd.app.errors import fail
from sctd.app.options import add_robot_argument
from sctd.wire.session import add_zenoh_arguments, session_from_args
from sctd_services.eval.cluster import ClusterError, Rerun, add_scheduler_arguments, executor_from_args

from .check import CheckSettings
from .store import Store
from .training import TrainingLimits

CLIENT_ROLE = "sctd-learner"  # the key pair of a sctd certs folder the learner presents to a cluster



NICE = 10
"""How much lower than the daemon's the learner's CPU priority is by default (``--nice``)."""

def add_arguments(p: argparse.ArgumentParser) -> None:
    """The learner's flags (``sctd learner``)."""
    d = CheckSettings()
    p.add_argument("--store", default=None, metavar="DIR",
                   help="the store of demonstrations and skills (default $SCTD_STORE, else "
                        "$XDG_DATA_HOME/sctd/store, else ~/.local/share/sctd/store)")
    add_robot_argument(p)
    g = p.add_argument_group("the check before a swap (sctd eval --lockstep, docs/learner.md)")
    g.add_argument("--trials", type=int, default=d.trials,
                   help="at most this many lockstep trials: a sequential test stops as soon as it "
                        "decides, after 6 for a skill that always succeeds (default %(default)s)")
    g.add_argument("--floor", type=float, default=d.floor,
                   help="the success rate the sequential test is around: it passes a skill of "
                        "half-way from it to 1, refuses one as far below it (default %(default)s)")
    g.add_argument("--tolerance", type=float, default=d.tolerance,
                   help="how much lower than the active skill's stored evaluation the new "
                        "one's success rate may be (default %(default)s)")
    g.add_argument("--seed", type=int, default=d.seed,
                   help="the trials' first seed (default %(default)s: sctd eval's and sctd suite's "
                        "seeds 0-19 stay held out)")
    g.add_argument("--jobs", type=int, default=d.jobs,
                   help="trial processes, kept warm (default %(default)s)")
    g.add_argument("--allow-unchecked", action="store_true",
                   help="let a request skip the check (gate: false; its skill is swapped in "
                        "unchecked and stored as such); without it such a request is refused")
    t = TrainingLimits()
    g = p.add_argument_group("each training (a child process)")
    g.add_argument("--train-timeout", type=float, default=t.timeout,
                   help="s a training may take before it is stopped and refused (default %(default)s)")
    g.add_argument("--train-memory-mb", type=int, default=t.memory // 1024**2,
                   help="MB of address space a training may use (default %(default)s)")
    p.add_argument("--nice", type=int, default=NICE,
                   help="lower this process's (and its trials') CPU priority by this much, so "
                        "training never competes with the daemon's tick (default %(default)s)")
    add_scheduler_arguments(p, CLIENT_ROLE)
    add_zenoh_arguments(p)


def _say_rerun(learner: list, rerun: Rerun) -> None:
    """A worker died with trials of the check on it: in the log and on learner/status."""
    logging.getLogger("sctd.learner").warning("%s", rerun)
    if learner:
        learner[0].say("rerun", worker=rerun.worker, trials=list(rerun.trials))


def run(args: argparse.Namespace) -> int:
    """Run the service until SIGINT/SIGTERM; exit code 2 for bad flags."""
    from .check import trial_pool
    from .service import Learner, Stopped, store_path
    from .training import Trainer

    try:
        settings = CheckSettings(args.trials, args.floor, args.tolerance, args.seed, args.jobs,
                                 args.allow_unchecked)
        limits = TrainingLimits(args.train_memory_mb * 1024**2, args.train_timeout)
        store = Store(store_path(args.store))
    except (ValueError, OSError) as e:
        return fail("learner", str(e))
    learner: list[Learner] = []
    try:  # the check's trials: on a Dask cluster (--scheduler), else local processes kept warm
        pool = executor_from_args(args, CLIENT_ROLE, lambda r: _say_rerun(learner, r))
    except ClusterError as e:
        return fail("learner", str(e))
    if args.nice > 0:
        os.nice(args.nice)
    logging.basicConfig(level=logging.INFO, format="sctd learner: %(message)s", stream=sys.stderr)
    stop = threading.Event()

    def on_signal(*_: object) -> None:
        stop.set()
        if learner and learner[0].busy is not None:
            raise Stopped  # in the service's thread: the request is answered, then we exit

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    if pool is None and settings.jobs > 1:  # after nice: the trial processes inherit it
        pool = trial_pool(settings.jobs)
    try:
        with session_from_args(args) as session, \
                Learner(session, store, args.robot, settings, pool, Trainer(limits)) as ln:
            ln.trainer.warm()  # (its worker's imports now, not in the first request's time)
            learner.append(ln)
            tasks = ", ".join(f"{t} ({n})" for t, n in store.tasks().items()) or "none yet"
            print(f"sctd learner: store {store.root}: demonstrations of {tasks}, "
                  f"{len(store.skills())} skill(s); answering {ln.keys.learner}",
                  file=sys.stderr, flush=True)
            ln.serve(stop)
    except Stopped:
        print("sctd learner: stopped while serving a request", file=sys.stderr)
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m sctd_services.learner``."""
    p = argparse.ArgumentParser(prog="sctd-learner", description=__doc__.split("\n\n")[0])
    add_arguments(p)
    return run(p.parse_args(argv))
