"""The daemon's ``skill`` queryable from the asking side: the active skill's summary,
and a swap (``sctd swap``, ``sctd skills swap``, the learner service)."""

from __future__ import annotations

from typing import Any

import msgpack
import zenoh

from ..skill import Bundle
from . import codec


def reply_body(data: bytes) -> dict[str, Any]:
    """A reply's msgpack map (``{error: ...}`` for anything else)."""
    try:
        body = msgpack.unpackb(data, raw=False)
    except Exception:  # msgpack raises several unrelated types
        return {"error": data.decode(errors="replace")}
    return body if isinstance(body, dict) else {"error": str(body)}


def active_skill(session: zenoh.Session, keys: codec.Keys, timeout: float = 3.0) -> dict[str, Any] | None:
    """The running daemon's skill summary (``sctd inspect --json`` plus ``state``), or
    None when no daemon answers within ``timeout`` s."""
    for reply in session.get(keys.skill, timeout=timeout):
        if reply.ok is not None:
            return reply_body(reply.ok.payload.to_bytes())
    return None


def swap(session: zenoh.Session, keys: codec.Keys, bundle: Bundle,
         timeout: float = 10.0) -> tuple[bool, dict[str, Any]]:
    """Send ``bundle`` to the daemon: (swapped, its reply ``{ok, id, name, state}`` or
    ``{error}``; when no daemon answers within ``timeout`` s, ``{error, unanswered: True}``)."""
    for reply in session.get(keys.skill, payload=bundle.pack(), timeout=timeout):
        sample = reply.ok if reply.ok is not None else reply.err
        if sample is not None:
            return reply.ok is not None, reply_body(sample.payload.to_bytes())
    return False, {"error": f"no daemon answered on {keys.skill} within {timeout:g} s",
                   "unanswered": True}
