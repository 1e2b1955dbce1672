"""Session defaults: loopback IP literals only without a config file; the runtime's
ingress limits are Zenoh filters that Zenoh accepts, and no rate limit touches what the
runtime reads; a helper's session connects where the program connects and listens, and
listens on an ephemeral loopback port of its own under the loopback defaults only."""

import json

import pytest

from sctd.runtime.daemon import check_no_rate_limit, ingress_limits
from sctd.wire.session import SessionSettings, check_loopback, helper_config, make_config


@pytest.mark.parametrize("endpoint", ["tcp/127.0.0.1:7447", "tcp/127.1.2.3:0", "tcp/[::1]:7447"])
def test_loopback_ip_literals_are_accepted(endpoint):
    check_loopback(endpoint)


@pytest.mark.parametrize("endpoint", [
    "tcp/127.attacker.example:7447",  # a name that merely starts with 127.
    "tcp/localhost:7447",  # whatever /etc/hosts says
    "tcp/10.0.0.1:7447", "tcp/0.0.0.0:7447", "tcp/[::]:7447", "tcp/[::ffff:10.0.0.1]:7447",
    "udp/127.0.0.1:7447", "tls/127.0.0.1:7447",
    "tcp/127.0.0.1", "tcp/127.0.0.1:", "tcp/127.0.0.1:port", "tcp/127.0.0.1:99999", "tcp/:7447",
])
def test_anything_else_is_refused_without_a_config_file(endpoint):
    with pytest.raises(ValueError, match="loopback"):
        check_loopback(endpoint)


def test_ingress_limits_become_zenoh_filters_and_nothing_limits_the_rate(tmp_path):
    """The daemon's session drops oversized puts on arrival and rate-limits nothing: a
    downsampling rule keeps the first message of an interval, and the rest may be a
    release. A config file that rate-limits what the daemon reads is refused."""
    conf = make_config(listen=["tcp/127.0.0.1:0"], **ingress_limits("edan"))
    lpf = json.loads(conf.get_json("low_pass_filter"))
    assert {k for f in lpf for k in f["key_exprs"]} == {"sctd/edan/input/**", "sctd/edan/state",
                                                         "sctd/edan/objects/**"}
    assert all(f["flows"] == ["ingress"] and f["size_limit"] == 16 << 20 for f in lpf)
    assert not json.loads(conf.get_json("downsampling") or "[]")
    check_no_rate_limit(conf, "edan")
    # a config file's own filters are kept, ours added
    f = tmp_path / "z.json5"
    f.write_text(json.dumps({"mode": "peer", "low_pass_filter": [
        {"id": "mine", "key_exprs": ["x/**"], "messages": ["put"], "flows": ["egress"], "size_limit": 10}]}))
    conf = make_config(config_file=f, **ingress_limits("edan"))
    ids = [x["id"] for x in json.loads(conf.get_json("low_pass_filter"))]
    assert ids[0] == "mine" and len(ids) == 4
    check_no_rate_limit(conf, "edan")


def _rule(name, key, flows=("ingress",)):
    r = {"id": name, "messages": ["put"], "rules": [{"key_expr": key, "freq": 500.0}]}
    if flows is not None:
        r["flows"] = list(flows)
    return r


@pytest.mark.parametrize("rule, refused", [
    (_rule("input", "sctd/edan/input/**"), True),
    (_rule("all", "**", flows=None), True),  # no flows: both ways
    (_rule("state", "sctd/*/state"), True),
    (_rule("out", "sctd/edan/input/**", flows=("egress",)), False),
    (_rule("other", "sctd/edan/status"), False),
    (_rule("robot", "sctd/other/input/*"), False),
])
def test_a_config_that_rate_limits_what_the_daemon_reads_is_refused(tmp_path, rule, refused):
    f = tmp_path / "z.json5"
    f.write_text(json.dumps({"mode": "peer", "downsampling": [rule]}))
    conf = make_config(config_file=f, **ingress_limits("edan"))
    if refused:
        with pytest.raises(ValueError, match=f"downsampling: {rule['id']}: rate-limits"):
            check_no_rate_limit(conf, "edan")
    else:
        check_no_rate_limit(conf, "edan")


def _endpoints(conf, key: str) -> list[str]:
    return json.loads(conf.get_json(key))


@pytest.mark.parametrize(("settings", "connect", "listen"), [
    (SessionSettings(), ["tcp/127.0.0.1:7447"], ["tcp/127.0.0.1:0"]),  # the hub; the rest through gossip
    (SessionSettings(listen=("tcp/127.0.0.1:4000",)), ["tcp/127.0.0.1:4000"], ["tcp/127.0.0.1:0"]),
    (SessionSettings(listen=("tcp/127.0.0.1:0",), connect=("tcp/127.0.0.1:4001",)), ["tcp/127.0.0.1:4001"],
     ["tcp/127.0.0.1:0"]),
    (SessionSettings(listen=("tcp/127.0.0.1:4000",), connect=("tcp/127.0.0.1:4000", "tcp/[::1]:4002")),
     ["tcp/127.0.0.1:4000", "tcp/[::1]:4002"], ["tcp/127.0.0.1:0"]),
    (SessionSettings(listen=("tcp/[::1]:4000",)), ["tcp/[::1]:4000"], ["tcp/[::1]:0"]),
])
def test_helper_config_connects_where_the_program_listens_and_connects(settings, connect, listen):
    """Under the loopback defaults the helper also listens, on an ephemeral port of the
    program's own loopback address."""
    conf = helper_config(settings)
    assert _endpoints(conf, "listen/endpoints") == listen
    assert _endpoints(conf, "connect/endpoints") == connect
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False


def test_helper_config_of_a_config_file_keeps_it_listens_nowhere_and_reaches_its_listeners(tmp_path):
    f = tmp_path / "z.json5"
    f.write_text(json.dumps({"mode": "peer", "scouting": {"multicast": {"enabled": False}},
                             "listen": {"endpoints": ["tcp/0.0.0.0:5555", "tcp/[::]:0", "tcp/10.1.2.3:5556"]},
                             "connect": {"endpoints": ["tcp/10.9.9.9:7447"]}}))
    conf = helper_config(SessionSettings(config_file=str(f)))
    assert _endpoints(conf, "listen/endpoints") == []
    assert _endpoints(conf, "connect/endpoints") == ["tcp/127.0.0.1:5555", "tcp/10.1.2.3:5556",
                                                     "tcp/10.9.9.9:7447"]
    assert json.loads(conf.get_json("mode")) == "peer"
    # a client of a router (the deployment's runtime): the same router, the same mode
    f.write_text(json.dumps({"mode": "client", "connect": {"endpoints": ["tcp/10.0.0.5:7448"]}}))
    conf = helper_config(SessionSettings(config_file=str(f)))
    assert _endpoints(conf, "connect/endpoints") == ["tcp/10.0.0.5:7448"]
    assert json.loads(conf.get_json("mode")) == "client"
