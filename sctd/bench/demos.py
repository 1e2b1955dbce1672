"""The generated demonstrations (``sctd_sim.demogen``) as the learner reads them: shared
by the learning benches (``learn``, ``fields``, ``gco``)."""

from __future__ import annotations

from sctd_sim import demogen

from ..learn import Demo
from ..task import find_task


def demo_kind(ref: str) -> demogen.Kind:
    """The generator's kind of the workload ``ref`` names (a bench's argument, or a name of
    ``bench_learn`` in ``sctd/app/defaults.yaml``): ``crank`` or ``wipe``
    (:data:`~sctd_sim.demogen.SYNTHETIC`), or a task's name or file, resolved here."""
    synthetic = demogen.SYNTHETIC.get(ref)
    return synthetic if synthetic is not None else demogen.kind_of(find_task(ref))


def demos_of(ds: demogen.DemoSet) -> list[Demo]:
    """The generated demonstrations as the learner reads them."""
    return [Demo(d.name, d.t, d.poses) for d in ds.demos]
