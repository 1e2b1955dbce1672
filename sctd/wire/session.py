"""Zenoh sessions with sctd's defaults: TCP on 127.0.0.1 only, no multicast scouting.

Without flags every sctd program is an identical peer that
- tries to hold ``tcp/127.0.0.1:7447`` (retrying in the background while another
  program has it, so when that one exits a survivor takes the port over),
- listens on an ephemeral loopback port that gossip scouting advertises to the others,
- connects to ``tcp/127.0.0.1:7447`` and retries forever.
So programs started in any order find each other, a plain Zenoh client that connects to
``tcp/127.0.0.1:7447`` reaches them, and they reconnect after any of them restarts.
``--listen`` / ``--connect`` replace the respective endpoint lists (tests use free
ports); ``--zenoh-config FILE`` replaces all of this for multi-host use.

A helper process that acts for a program on the network (the daemon's skill server,
:mod:`sctd.runtime.skillserver`) opens its session from the same settings with
:func:`helper_config`: it connects where the program connects and listens, and under
the loopback defaults listens on an ephemeral loopback port of its own.
"""

from __future__ import annotations

import ipaddress
import json
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import zenoh

HUB = "tcp/127.0.0.1:7447"
_RETRY = '{"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}'


# What every sctd publication declares it carries (Zenoh ``Encoding``), so generic Zenoh
# tools know: the wire contract's messages are msgpack (docs/wire-contract.md); the
# benchmarks' ping/pong are text.
MSGPACK = zenoh.Encoding("application/msgpack")
TEXT = zenoh.Encoding.TEXT_PLAIN


def is_loopback(host: str) -> bool:
    """Whether ``host`` is a loopback address: an IP literal in 127.0.0.0/8 or ``::1``, or
    ``localhost`` (for a server to bind to: no name is looked up)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_loopback(endpoint: str) -> None:
    """Refuse endpoints that are not TCP on a loopback IP literal (127.0.0.0/8 or
    ``[::1]``), with a port: names are not accepted, since a name can resolve anywhere
    (``127.attacker.example``; ``localhost`` is whatever /etc/hosts says)."""
    proto, _, rest = endpoint.partition("/")
    host, colon, port = rest.rpartition(":")
    ok = proto == "tcp" and bool(colon) and port.isdigit() and 0 <= int(port) <= 65535
    if ok:
        if host.startswith("[") and host.endswith("]"):
            host = host[1:-1]
        try:
            ok = ipaddress.ip_address(host).is_loopback
        except ValueError:
            ok = False
    if not ok:
        raise ValueError(
            f"endpoint {endpoint!r}: only tcp/<loopback IP>:<port> (127.0.0.0/8 or [::1]) without "
            "--zenoh-config (use a Zenoh config file for other hosts)"
        )


def make_config(listen: Sequence[str] | None = None, connect: Sequence[str] | None = None,
                config_file: str | Path | None = None,
                size_limits: Sequence[tuple[str, int]] = (),
                rate_limits: Sequence[tuple[str, float]] = ()) -> zenoh.Config:
    """Build the session config (see module doc).

    ``size_limits``: (key expression, bytes) pairs; puts larger than that arriving on a
    matching key are dropped by Zenoh on arrival (its low-pass filter), before any Python
    sees them. ``rate_limits``: (key expression, Hz) pairs; puts arriving on matching
    keys faster than that, all such keys together, are dropped on arrival (Zenoh's
    downsampling). Both are added to a config file's own filters.
    """
    if config_file is not None:
        conf = zenoh.Config.from_file(str(config_file))
        for key, eps in (("listen", listen), ("connect", connect)):
            if eps:
                conf.insert_json5(f"{key}/endpoints", json.dumps(list(eps)))
        _add_ingress_limits(conf, size_limits, rate_limits)
        return conf
    for ep in [*(listen or []), *(connect or [])]:
        check_loopback(ep)
    if listen is None and connect is None:
        listen_eps, connect_eps = [HUB, "tcp/127.0.0.1:0"], [HUB]
    else:
        listen_eps = list(listen) if listen else ["tcp/127.0.0.1:0"]
        connect_eps = list(connect or [])
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "true")
    conf.insert_json5("transport/link/protocols", '["tcp"]')
    # Shared memory would leave segments in /dev/shm after a kill; loopback TCP is fast.
    conf.insert_json5("transport/shared_memory/enabled", "false")
    conf.insert_json5("scouting/gossip/autoconnect", '{"router": [], "peer": ["router", "peer"]}')
    conf.insert_json5("listen/endpoints", json.dumps(listen_eps))
    conf.insert_json5("listen/timeout_ms", "-1")
    conf.insert_json5("listen/exit_on_failure", "false")
    conf.insert_json5("listen/retry", _RETRY)
    conf.insert_json5("connect/endpoints", json.dumps(connect_eps))
    conf.insert_json5("connect/timeout_ms", "-1")
    conf.insert_json5("connect/exit_on_failure", "false")
    conf.insert_json5("connect/retry", _RETRY)
    _add_ingress_limits(conf, size_limits, rate_limits)
    return conf


@dataclass(frozen=True)
class SessionSettings:
    """What a program's session is opened from: ``--listen``, ``--connect`` and
    ``--zenoh-config`` (None: not given)."""

    listen: tuple[str, ...] | None = None
    connect: tuple[str, ...] | None = None
    config_file: str | None = None

    @classmethod
    def from_args(cls, args) -> SessionSettings:
        def endpoints(v: Sequence[str] | None) -> tuple[str, ...] | None:
            return None if v is None else tuple(v)
        return cls(endpoints(args.listen), endpoints(args.connect),
                   None if args.zenoh_config is None else str(args.zenoh_config))


def helper_config(settings: SessionSettings) -> zenoh.Config:
    """The config of a helper's session: one that joins the network a session opened
    from ``settings`` joins, on the program's behalf. The same config (mode, scouting,
    TLS, access credentials), with the endpoints that session listens on added to those
    it connects to (an unspecified address as loopback, ``0.0.0.0`` as ``127.0.0.1`` and
    ``[::]`` as ``[::1]``; port 0, an ephemeral port, left out: gossip scouting finds
    it). It listens on an ephemeral port of the program's loopback address under the
    loopback defaults (no config file), so that a peer which hears of it by gossip can
    open the link as well as it can: a link that only one side may open is lost when
    that side's attempt is. With a config file it listens nowhere (a deployment's
    listeners are its own to choose); it then reaches every peer that listens and,
    through routers and the peers it connects to, every client."""
    conf = make_config(settings.listen, settings.connect, settings.config_file)
    listening = _endpoints(conf, "listen/endpoints")
    targets: list[str] = []
    for ep in [*(_as_target(ep) for ep in listening), *_endpoints(conf, "connect/endpoints")]:
        if ep is not None and ep not in targets:
            targets.append(ep)
    own = [] if settings.config_file is not None else [_ephemeral_like(listening[0])]
    conf.insert_json5("listen/endpoints", json.dumps(own))
    conf.insert_json5("connect/endpoints", json.dumps(targets))
    return conf


def _ephemeral_like(endpoint: str) -> str:
    """An ephemeral port on the host of ``endpoint`` (a checked loopback ``tcp/host:port``)."""
    host = endpoint.partition("/")[2].rpartition(":")[0]
    return f"tcp/{host}:0"


def _endpoints(conf: zenoh.Config, key: str) -> list[str]:
    """A config's endpoint list (a list, or one list per mode: the config's mode's)."""
    try:
        value = json.loads(conf.get_json(key))
        if isinstance(value, dict):
            value = value.get(json.loads(conf.get_json("mode")) or "peer")
    except (zenoh.ZError, ValueError):
        return []
    return [ep for ep in value if isinstance(ep, str)] if isinstance(value, list) else []


_UNSPECIFIED = {"0.0.0.0": "127.0.0.1", "[::]": "[::1]"}


def _as_target(endpoint: str) -> str | None:
    """A listen endpoint as an endpoint to connect to it on this host (None: port 0)."""
    cut = min((i for i in (endpoint.find("?"), endpoint.find("#")) if i >= 0), default=len(endpoint))
    locator, rest = endpoint[:cut], endpoint[cut:]
    proto, slash, address = locator.partition("/")
    host, colon, port = address.rpartition(":")
    if not slash or not colon or not port.isdigit():
        return endpoint  # no host:port (a unix socket path): as it is
    if int(port) == 0:
        return None
    return f"{proto}/{_UNSPECIFIED.get(host, host)}:{port}{rest}"


def _config_list(conf: zenoh.Config, key: str) -> list:
    try:
        return json.loads(conf.get_json(key)) or []
    except (zenoh.ZError, ValueError):
        return []


def _add_ingress_limits(conf: zenoh.Config, size_limits: Sequence[tuple[str, int]],
                        rate_limits: Sequence[tuple[str, float]]) -> None:
    if size_limits:
        filters = _config_list(conf, "low_pass_filter")
        for i, (key, limit) in enumerate(size_limits):
            filters.append({"id": f"sctd-size-{i}", "key_exprs": [key], "messages": ["put"],
                            "flows": ["ingress"], "size_limit": int(limit)})
        conf.insert_json5("low_pass_filter", json.dumps(filters))
    if rate_limits:
        rules = _config_list(conf, "downsampling")
        for i, (key, hz) in enumerate(rate_limits):
            rules.append({"id": f"sctd-rate-{i}", "messages": ["put"], "flows": ["ingress"],
                          "rules": [{"key_expr": key, "freq": float(hz)}]})
        conf.insert_json5("downsampling", json.dumps(rules))


def open_session(listen: Sequence[str] | None = None, connect: Sequence[str] | None = None,
                 config_file: str | Path | None = None,
                 size_limits: Sequence[tuple[str, int]] = (),
                 rate_limits: Sequence[tuple[str, float]] = ()) -> zenoh.Session:
    """Open a Zenoh session with :func:`make_config`; close it with :func:`close_session`
    (or use :func:`session`, a context manager that does)."""
    return zenoh.open(make_config(listen, connect, config_file, size_limits, rate_limits))


def close_session(s: zenoh.Session, timeout: float = 1.0) -> bool:
    """Close a session within ``timeout`` seconds; False if Zenoh did not finish.

    A program that is still retrying to bind ``tcp/127.0.0.1:7447`` in the background
    (another one holds it) cannot cancel that retry, and ``Session.close`` then blocks
    for about 10 s before failing. Closing from a helper thread bounds the wait; the
    process can exit regardless.
    """
    t = threading.Thread(target=_close_quietly, args=(s,), name="zenoh-close", daemon=True)
    t.start()
    t.join(timeout)
    return not t.is_alive()


def _close_quietly(s: zenoh.Session) -> None:
    try:
        s.close()
    except zenoh.ZError:  # "close operation timed out!": nothing left to do
        pass


@contextmanager
def session(listen: Sequence[str] | None = None, connect: Sequence[str] | None = None,
            config_file: str | Path | None = None,
            rate_limits: Sequence[tuple[str, float]] = ()) -> Iterator[zenoh.Session]:
    """``with session(...) as s:`` an open session, closed with a bounded wait
    (``rate_limits``: see :func:`make_config`)."""
    s = open_session(listen, connect, config_file, rate_limits=rate_limits)
    try:
        yield s
    finally:
        close_session(s)


def add_zenoh_arguments(parser) -> None:
    """The common ``--listen/--connect/--zenoh-config`` flags of every sctd program."""
    g = parser.add_argument_group("zenoh")
    g.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help="listen endpoint (repeatable), e.g. tcp/127.0.0.1:7447")
    g.add_argument("--connect", action="append", metavar="ENDPOINT",
                   help="connect endpoint (repeatable), e.g. tcp/127.0.0.1:7447")
    g.add_argument("--zenoh-config", metavar="FILE",
                   help="Zenoh json5 config file replacing the loopback defaults")


def session_from_args(args, rate_limits: Sequence[tuple[str, float]] = ()):
    """``with session_from_args(args) as s:`` for the common Zenoh flags."""
    return session(args.listen, args.connect, args.zenoh_config, rate_limits)
