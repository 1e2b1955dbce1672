"""The learner's training request (the ``sctd/<robot>/learner`` query payload), checked
field by field before any work starts."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from sctd.learn import METHODS, HyperparameterError, check_hyperparameters, hyperparameter_names
from sctd.learn.pipeline import hyperparameter_fields
from sctd.wire import codec
from sctd.wire.client import MEMBER_NAME_RULE, member_name_ok

FIELDS = ("task", "method", "object", "frames", "params", "demos", "gate", "name", "swap", "seed",
          "member", "v")


class RequestError(ValueError):
    """A malformed request: ``field: what is wrong``."""

    def __init__(self, where: str, problem: str):
        super().__init__(f"{where}: {problem}")


@dataclass(frozen=True)
class Request:
    """What to train, from which demonstrations, and whether to check and swap it."""

    task: str
    method: str
    object: str | None = None
    frames: dict[str, list[float]] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)  # by hyperparameter field name
    demos: list[str] | None = None  # None: every demonstration of the task
    gate: bool = True
    name: str | None = None  # default: <task>-<method>-learned
    swap: bool = True
    seed: int | None = None  # the check's first trial seed (default: the learner's)
    member: str | None = None  # the skill set's member it replaces (default: services/learner/member.py)

    @property
    def skill_name(self) -> str:
        return self.name or f"{self.task}-{self.method}-learned"


def _chunk(value: Any, where: str) -> str:
    problem = codec.name_problem(value)
    if problem:
        raise RequestError(where, problem)
    return value


def parse_frame(text: Any) -> tuple[str, list[float]]:
    """``NAME=x,y,z,qx,qy,qz,qw`` (as ``sctd learn --frame``) -> (name, pose); the
    quaternion must be unit."""
    if not isinstance(text, str):
        raise RequestError("frames", f"expected NAME=x,y,z,qx,qy,qz,qw strings, got {text!r}")
    name, sep, rest = text.partition("=")
    if not sep or not name:
        raise RequestError("frames", f"{text!r}: expected NAME=x,y,z,qx,qy,qz,qw")
    try:
        vals = [float(x) for x in rest.split(",")]
    except ValueError:
        raise RequestError("frames", f"{text!r}: values must be numbers") from None
    if len(vals) != 7 or not all(math.isfinite(v) for v in vals):
        raise RequestError("frames", f"{text!r}: expected 7 finite numbers, got {len(vals)}")
    if abs(math.sqrt(sum(q * q for q in vals[3:])) - 1.0) > 1e-3:
        raise RequestError("frames", f"{text!r}: quaternion must be unit")
    if name in ("ee", "object"):
        raise RequestError("frames", f"{text!r}: {name!r} is built in")
    return name, vals


def param_aliases(method: str) -> dict[str, str]:
    """Every name a hyperparameter may be given by -> its field name: the field name,
    ``sctd learn``'s flag without its dashes (``vf-combine``, ``seed``), and the flag
    with underscores."""
    out: dict[str, str] = {}
    for f in hyperparameter_fields(method):
        flag = f.metadata.get("flag", "--" + f.name.replace("_", "-")).lstrip("-")
        if flag.startswith("no-") and not f.name.startswith("no_"):
            flag = f.name  # a flag that clears its field is no alias: the field's name is
        for alias in (f.name, flag, flag.replace("-", "_"), f.name.replace("_", "-")):
            out.setdefault(alias, f.name)
    return out


MAX_NAMES = 16  # names in a list-valued hyperparameter (vf-models has 5 to choose from)


def _names(v: Any, where: str) -> tuple[str, ...]:
    """A list-valued hyperparameter (``vf-models``): a list of names or ``"a,b,c"``."""
    if isinstance(v, str):
        v = [x.strip() for x in v.split(",")]
    if not isinstance(v, list | tuple) or not 0 < len(v) <= MAX_NAMES or not all(
            isinstance(x, str) and 0 < len(x) <= 64 for x in v):
        raise RequestError(where, f"expected a list of at most {MAX_NAMES} names (or \"a,b,c\"), got "
                                  f"{str(v)[:80]}")
    return tuple(v)


def _params(value: Any, method: str) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise RequestError("params", "expected a map of hyperparameter name -> value")
    aliases = param_aliases(method)
    lists = {f.name for f in hyperparameter_fields(method)
             if getattr(f.metadata.get("valid"), "subset", False)}
    out: dict[str, Any] = {}
    for k, v in value.items():
        name = aliases.get(str(k).lstrip("-"))
        if name is None:
            raise RequestError(f"params.{k}", f"not a hyperparameter of method {method!r} (known: "
                                              f"{', '.join(hyperparameter_names(method))})")
        if name in lists:  # a list of names, or the flag's comma-separated form: checked below
            v = _names(v, f"params.{k}")
        elif not isinstance(v, bool | int | float | str) or (isinstance(v, float) and not math.isfinite(v)):
            raise RequestError(f"params.{k}", f"expected a finite number, a string or a bool, got {v!r}")
        out[name] = v
    try:
        check_hyperparameters(method, out)
    except HyperparameterError as e:
        alias = next(k for k in value if aliases.get(str(k).lstrip("-")) == e.name)
        raise RequestError(f"params.{alias}", e.problem) from None
    return out


def _frames(value: Any, method: str) -> dict[str, list[float]]:
    if value is None:
        return {}
    if method != "linear":
        raise RequestError("frames", "candidate frames are for linear IMs; vector fields find their own")
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list):
        raise RequestError("frames", "expected a list of NAME=x,y,z,qx,qy,qz,qw strings")
    return dict(parse_frame(t) for t in value)


def _member(value: Any) -> str | None:
    """A skill set's member, as the daemon's ``skill/swap?member=NAME`` takes it."""
    if value is None:
        return None
    if not isinstance(value, str):
        raise RequestError("member", f"expected a skill set member's name, got {value!r}")
    if not member_name_ok(value):
        raise RequestError("member", f"{value!r}: {MEMBER_NAME_RULE}")
    return value


def _flag(obj: dict, key: str, default: bool) -> bool:
    value = obj.get(key, default)
    if not isinstance(value, bool):
        raise RequestError(key, f"expected true or false, got {value!r}")
    return value


def parse_request(data: bytes) -> Request:
    """Decode and check a request (a msgpack map).

    Raises
    ------
    RequestError
        Naming the field: not a map, an unknown field, a missing ``task``/``method``,
        a bad value.
    """
    try:
        obj = codec.unpack_map(data)
    except codec.DecodeError as e:
        raise RequestError("<request>", f"not a msgpack map ({e})") from None
    unknown = sorted(str(k) for k in obj if k not in FIELDS)
    if unknown:
        raise RequestError(unknown[0], f"unknown field (known: {', '.join(FIELDS[:-1])})")
    task = _chunk(obj.get("task"), "task")
    method = obj.get("method")
    if method not in METHODS:
        raise RequestError("method", f"expected one of {', '.join(METHODS)}, got {method!r}")
    demos = obj.get("demos")
    if demos is not None and (not isinstance(demos, list) or not demos):
        raise RequestError("demos", "expected a non-empty list of demonstration names")
    seed = obj.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise RequestError("seed", f"expected an integer >= 0, got {seed!r}")
    return Request(
        task=task, method=method,
        object=None if obj.get("object") is None else _chunk(obj["object"], "object"),
        frames=_frames(obj.get("frames"), method), params=_params(obj.get("params"), method),
        demos=None if demos is None else [_chunk(d, "demos") for d in demos],
        gate=_flag(obj, "gate", True), swap=_flag(obj, "swap", True),
        name=None if obj.get("name") is None else _chunk(obj["name"], "name"), seed=seed,
        member=_member(obj.get("member")))


def request_map(req: Request) -> dict[str, Any]:
    """The request as plain data (for the record and the status)."""
    d = dataclasses.asdict(req)
    d["frames"] = [f"{k}=" + ",".join(f"{x:g}" for x in v) for k, v in req.frames.items()]
    return d
