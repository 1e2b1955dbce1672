"""Session defaults: loopback IP literals only without a config file; the runtime's
ingress limits are Zenoh filters that Zenoh accepts."""

import json

import pytest

from sctd.runtime.daemon import ingress_limits
from sctd.runtime.zsession import check_loopback, make_config


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


def test_ingress_limits_become_zenoh_filters(tmp_path):
    conf = make_config(listen=["tcp/127.0.0.1:0"], **ingress_limits("edan"))
    lpf = json.loads(conf.get_json("low_pass_filter"))
    ds = json.loads(conf.get_json("downsampling"))
    assert {k for f in lpf for k in f["key_exprs"]} == {"sctd/edan/input/**", "sctd/edan/state",
                                                         "sctd/edan/objects/**"}
    assert all(f["flows"] == ["ingress"] and f["size_limit"] == 16 << 20 for f in lpf)
    assert {r["rules"][0]["key_expr"]: r["rules"][0]["freq"] for r in ds} == {
        "sctd/edan/input/**": 2000.0, "sctd/edan/state": 4000.0, "sctd/edan/objects/**": 2000.0}
    # a config file's own filters are kept, ours added
    f = tmp_path / "z.json5"
    f.write_text(json.dumps({"mode": "peer", "low_pass_filter": [
        {"id": "mine", "key_exprs": ["x/**"], "messages": ["put"], "flows": ["egress"], "size_limit": 10}]}))
    conf = make_config(config_file=f, **ingress_limits("edan"))
    ids = [x["id"] for x in json.loads(conf.get_json("low_pass_filter"))]
    assert ids[0] == "mine" and len(ids) == 4
