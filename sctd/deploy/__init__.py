"""sctd across hosts: the Zenoh configs of each role, and a cluster of hosts on one
machine in Linux network namespaces, each host running sctd's programs as a Zenoh
client of one router.

- ``zenoh/`` (package data): the router's and every role's config templates, which
  ``sctd certs`` renders, and ``loopback.json5``, the defaults written out;
- :mod:`~sctd.deploy.netns`: the hosts (``Hosts``: namespaces joined by a bridge,
  programs run inside them, links taken down and up);
- :mod:`~sctd.deploy.configs`: plain and TLS Zenoh client configs, client certificates;
- :mod:`~sctd.deploy.probe`: the Zenoh probe run inside a host
  (``python -m sctd.deploy.probe``);
- :mod:`~sctd.deploy.linkfault` and :mod:`~sctd.deploy.linkproxy`: the faults of a real
  link (delay, jitter, stalls, bandwidth, resets, datagram loss; seeded) and the proxy
  that makes them in user space, between two hosts or on loopback;
- :mod:`~sctd.deploy.cluster`: ``Cluster``, sctd's programs on those hosts, which
  ``tests/test_multihost.py`` checks and ``sctd bench multihost`` measures.

Application code: it starts processes and needs root for ``ip netns``; nothing below
the command line imports it.
"""
