"""``sctd train``: ask the learner service to train, check and swap a skill.

Sends one request to ``sctd/<robot>/learner`` (docs/learner.md), prints the learner's
progress from ``sctd/<robot>/learner/status`` while it works, then the reply: the
skill's id, whether it was swapped and why, and the check's table.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from ..app.errors import EXIT_FAILED, EXIT_OK, fail
from ..app.options import add_robot_argument
from ..files import FileError, parse_yaml
from ..wire import Keys, client, codec
from ..wire.session import add_zenoh_arguments, session_from_args

DEFAULT_TIMEOUT = 120.0


def add_train_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--task", required=True, help="the task whose stored demonstrations to learn from")
    p.add_argument("--method", required=True, choices=("linear", "vf"),
                   help="linear input mappings (Ch. 4.1) or vector fields (Ch. 4.2)")
    p.add_argument("--object", default=None, help="task object (default: the demonstrations')")
    p.add_argument("--frame", action="append", default=None, metavar="NAME=x,y,z,qx,qy,qz,qw",
                   help="candidate feature frame for linear IMs, as sctd learn --frame (repeatable)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="a hyperparameter by sctd learn's name, e.g. vf-combine=intent or "
                        "smoothness=0.005 (repeatable)")
    p.add_argument("--demos", action="append", default=None, metavar="NAME",
                   help="learn from these stored demonstrations only (repeatable; default all "
                        "of the task)")
    p.add_argument("--name", default=None, help="the skill's name (default <task>-<method>-learned)")
    p.add_argument("--member", default=None, metavar="NAME",
                   help="with a skill set running: the member the skill replaces (default: the member "
                        "of the skill's name, else the one member tied to its object; a daemon running one "
                        "skill refuses it)")
    p.add_argument("--seed", type=int, default=None, help="the check's first trial seed (default: "
                                                          "the learner's)")
    p.add_argument("--no-gate", dest="gate", action="store_false",
                   help="swap without the lockstep check (only where the learner was started with "
                        "--allow-unchecked; refused otherwise)")
    p.add_argument("--no-swap", dest="swap", action="store_false",
                   help="train, check and store; do not swap")
    add_robot_argument(p)
    p.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT,
                   help="s to wait for the learner's reply (default %(default)s; training and the "
                        "check take tens of seconds)")
    p.add_argument("--find", type=float, default=client.FIND,
                   help="s to wait for the learner to be found before giving up (default %(default)s)")
    p.add_argument("--json", action="store_true", help="print the reply as JSON on stdout")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    add_zenoh_arguments(p)


def _value(text: str) -> Any:
    """A hyperparameter's value as YAML reads a scalar: 0.005, 3, true, intent."""
    try:
        v = parse_yaml(text, "--param")
    except FileError:
        return text
    return v if isinstance(v, bool | int | float | str) else text


def request_of(args: argparse.Namespace) -> dict[str, Any]:
    """The request map the flags describe (``ValueError`` for a malformed ``--param``)."""
    params = {}
    for item in args.param:
        name, eq, value = item.partition("=")
        if not eq or not name:
            raise ValueError(f"--param {item!r}: expected NAME=VALUE")
        params[name] = _value(value)
    req: dict[str, Any] = {"task": args.task, "method": args.method, "gate": args.gate, "swap": args.swap}
    for key, value in (("object", args.object), ("frames", args.frame), ("demos", args.demos),
                       ("name", args.name), ("seed", args.seed), ("member", args.member),
                       ("params", params or None)):
        if value is not None:
            req[key] = value
    return req


def progress_line(msg: dict[str, Any]) -> str | None:
    """A line for one status message of the learner (None for the periodic state)."""
    ev = msg.get("event")
    if ev == "training":
        return f"training {msg.get('task')}: {msg.get('stage')}"
    if ev == "trained":
        return f"trained {msg.get('name')}@{msg.get('id')}"
    if ev == "checking":
        return f"checking: trial {msg.get('trial')}/{msg.get('of')}"
    if ev == "swapping":
        member = msg.get("member")
        return f"swapping {msg.get('id')} into the daemon" + (
            "" if member is None else f" in place of the member {member!r}")
    return None


def main_train(args: argparse.Namespace) -> int:
    try:
        req = request_of(args)
    except ValueError as e:
        return fail("train", str(e))
    keys = Keys(args.robot)

    def on_status(sample: Any) -> None:
        try:
            line = progress_line(codec.unpack_map(sample.payload.to_bytes()))
        except codec.DecodeError:
            return
        if line and not args.quiet:
            print(f"sctd train: {line}", file=sys.stderr, flush=True)

    with session_from_args(args) as session, session.declare_subscriber(keys.learner_status, on_status):
        got = client.query(session, keys.learner, codec.pack(req), args.timeout, find=args.find)
    if got is None:
        return fail("train", f"no learner answered on {keys.learner} (none found within {args.find:g} s: "
                             "is sctd learner running on this robot prefix?)", EXIT_FAILED)
    ok, body = got
    if ok:
        return _print_reply(body, args.json, args.swap)
    if body.get("error") == "Timeout":  # Zenoh's own reply when the query timed out
        return fail("train", f"no reply within {args.timeout:g} s: the learner is still working and "
                             f"will finish (see {keys.learner_status} and sctd skills); give a longer "
                             "--timeout", EXIT_FAILED)
    return fail("train", f"refused by the learner: {body.get('error', body)}")


def _print_reply(body: dict[str, Any], as_json: bool, swap: bool) -> int:
    """Print the reply; 0 when it did what was asked (swapped, or with ``--no-swap``
    passed its check), else 1."""
    if as_json:
        print(json.dumps(body))
    else:
        t = body.get("timings", {})
        print(f"{body.get('ref')}: {'swapped' if body.get('swapped') else 'not swapped'}: "
              f"{body.get('reason')}")
        print(f"  trained in {t.get('train_s', 0):.1f} s, checked in {t.get('check_s', 0):.1f} s, "
              f"swapped in {t.get('swap_s', 0):.2f} s ({t.get('total_s', 0):.1f} s in all)")
        for row in (body.get("evaluation") or {}).get("table", []):
            print(f"  {row}")
        print(f"  stored as {body.get('path')}")
    if body.get("checked") is False and not as_json:
        print("  NOT CHECKED: the learner's operator lets requests skip the check")
    done = body.get("swapped") if swap else body.get("passed")
    return EXIT_OK if done else EXIT_FAILED
