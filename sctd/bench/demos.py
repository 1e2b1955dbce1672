"""The generated demonstrations (``sctd_sim.demogen``) as the learner reads them: shared
by the learning benches (``learn``, ``fields``, ``gco``)."""

from __future__ import annotations

from sctd_sim import demogen

from ..learn import Demo


def demos_of(ds: demogen.DemoSet) -> list[Demo]:
    """The generated demonstrations as the learner reads them."""
    return [Demo(d.name, d.t, d.poses) for d in ds.demos]
