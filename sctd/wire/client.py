"""Queries from the asking side: the daemon's ``skill`` queryable (the active skill's
summary) and ``skill/swap`` (a swap: ``sctd swap``, ``sctd skills swap``, the learner
service), and any
other queryable of the contract (``sctd train`` asks the learner).

A session that has just opened has not yet heard of the queryables its peers declared,
and a ``get`` sent then finds none and ends at once, unanswered. :func:`query` waits
until a queryable matches the key (Zenoh's matching status), for at most ``find``
seconds, before it asks.
"""

from __future__ import annotations

import time
from typing import Any

import msgpack
import zenoh

from ..skill import Bundle, SkillError
from . import Keys
from .session import MSGPACK

FIND = 5.0  # s to wait for a queryable to become known before giving up
MEMBER = "member"
"""The selector parameter that names a skill set's member: ``skill/swap?member=NAME``
(the member a swap replaces), ``skill/bundle?member=NAME`` (its bundle)."""
MEMBER_NAME_FORBIDDEN = ";=|&#?"
MEMBER_NAME_RULE = (f"a member named in a selector is printable and has none of {MEMBER_NAME_FORBIDDEN}; "
                    "swap a skill of the member's own name without naming it")


def reply_body(data: bytes) -> dict[str, Any]:
    """A reply's msgpack map (``{error: ...}`` for anything else)."""
    try:
        body = msgpack.unpackb(data, raw=False)
    except Exception:  # msgpack raises several unrelated types
        return {"error": data.decode(errors="replace")}
    return body if isinstance(body, dict) else {"error": str(body)}


def query(session: zenoh.Session, key: str, payload: bytes | None = None, timeout: float = 10.0,
          find: float = FIND, parameters: str | None = None) -> tuple[bool, dict[str, Any]] | None:
    """One ``get`` on ``key`` (with the selector's ``parameters``) once a queryable
    matches it: (ok, the reply's map; an error reply's is ``{error}``, Zenoh's own
    timeout ``{error: "Timeout"}``), or None when no queryable was known within ``find``
    s or none replied."""
    with session.declare_querier(key, timeout=timeout) as querier:
        give_up = time.monotonic() + find
        while not querier.matching_status.matching:  # type: ignore[attr-defined]
            if time.monotonic() > give_up:
                return None
            time.sleep(0.02)
        for reply in querier.get(payload=payload, encoding=None if payload is None else MSGPACK,
                                 parameters=parameters):
            sample = reply.ok if reply.ok is not None else reply.err
            if sample is not None:
                return reply.ok is not None, reply_body(sample.payload.to_bytes())
    return None


def active_skill(session: zenoh.Session, keys: Keys, timeout: float = 3.0,
                 find: float = FIND) -> dict[str, Any] | None:
    """The running daemon's skill summary (``sctd inspect --json`` plus ``state``), or
    None when no daemon answers."""
    got = query(session, keys.skill, None, timeout, find)
    return got[1] if got is not None and got[0] else None


def active_bundle(session: zenoh.Session, keys: Keys, timeout: float = 10.0,
                  find: float = FIND) -> tuple[Bundle, dict[str, Any]] | str:
    """The running daemon's active skill as its bundle (``get skill/bundle``, which an
    observer may ask), with the reply's ``{v, id, name, state}``; or why not, as a
    sentence. The bundle is unpacked with the size limits of a swap
    (:meth:`~sctd.skill.Bundle.unpack`)."""
    got = query(session, keys.skill_bundle, None, timeout, find)
    if got is None:
        return f"no daemon answered on {keys.skill_bundle} (none found within {find:g} s, or no reply)"
    ok, body = got
    if not ok:
        return str(body.get("error"))
    if body.get("v") != 1 or not isinstance(body.get("bundle"), bytes):
        return f"{keys.skill_bundle}: unexpected reply (v {body.get('v')!r})"
    try:
        bundle = Bundle.unpack(body["bundle"])
    except SkillError as e:
        return f"{keys.skill_bundle}: {e}"
    return bundle, {k: body.get(k) for k in ("v", "id", "name", "state")}


def member_name_ok(name: str) -> bool:
    """Whether a skill set's member can be named in a selector (``member=NAME``)."""
    return bool(name) and name.isprintable() and not any(c in name for c in MEMBER_NAME_FORBIDDEN)


def swap(session: zenoh.Session, keys: Keys, bundle: Bundle, timeout: float = 10.0,
         find: float = FIND, member: str | None = None) -> tuple[bool, dict[str, Any]]:
    """Send ``bundle`` to the daemon: (swapped, its reply ``{ok, id, name, state,
    [member]}`` or ``{error}``; when no daemon answers, ``{error, unanswered: True}``).
    ``member``: the daemon's skill set's member it replaces (:func:`member_name_ok`)."""
    if member is not None and not member_name_ok(member):
        return False, {"error": f"member {member!r}: {MEMBER_NAME_RULE}"}
    parameters = None if member is None else f"{MEMBER}={member}"
    got = query(session, keys.skill_swap, bundle.pack(), timeout, find, parameters)
    if got is None:
        return False, {"error": f"no daemon answered on {keys.skill_swap} (none found within "
                                f"{find:g} s, or no reply within {timeout:g} s)", "unanswered": True}
    return got
