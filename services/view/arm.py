"""The arm as its links' shapes: the URDF's ``<visual>`` geometry, posed by the joints.

The shipped URDF (``sctd_sim.robot.URDF_PATH``) describes each link's visual as a
primitive (cylinders along the links, the hand a box with two fingers); any URDF whose
visuals are boxes, cylinders or spheres works the same. Pinocchio reads them
(``buildGeomFromUrdf``) and places them for joint positions ``q`` (forward kinematics),
in a workspace of the view's own.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
import trimesh
from numpy.typing import NDArray

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Link:
    """One visual of the arm: its mesh (vertices (n, 3) in the visual's frame, faces)
    and colour (RGB 0-255)."""

    name: str
    vertices: Array
    faces: NDArray[np.int64]
    rgb: tuple[int, int, int]


class ArmGeometry:
    """The visuals of a URDF and their poses for joint positions.

    Parameters
    ----------
    urdf : str or Path
        A URDF whose ``<visual>`` elements are boxes, cylinders or spheres (others are
        left out, named in :attr:`skipped`).
    """

    def __init__(self, urdf: str | Path):
        self.model = pin.buildModelFromUrdf(str(urdf))
        self.geometry = pin.buildGeomFromUrdf(self.model, str(urdf), pin.GeometryType.VISUAL)
        self.data = self.model.createData()
        self.geometry_data = pin.GeometryData(self.geometry)
        self.links: list[Link] = []
        self._index: list[int] = []
        self.skipped: list[str] = []
        for i, g in enumerate(self.geometry.geometryObjects):
            mesh = _mesh(g.geometry)
            if mesh is None:
                self.skipped.append(g.name)
                continue
            r, g_, b = (round(255 * float(c)) for c in np.asarray(g.meshColor)[:3])
            self.links.append(Link(g.name, np.asarray(mesh.vertices, dtype=float),
                                   np.asarray(mesh.faces, dtype=np.int64), (r, g_, b)))
            self._index.append(i)

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    def poses(self, q: Array) -> list[Array]:
        """Each link's pose in the world (4, 4) for joint positions ``q`` (nq,)."""
        pin.forwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry_data)
        return [self.geometry_data.oMg[i].homogeneous.copy() for i in self._index]


def _mesh(shape) -> trimesh.Trimesh | None:
    """A primitive's mesh in its own frame (coal's conventions: a cylinder along z,
    centred; a box by its half sides), or None for another kind."""
    kind = type(shape).__name__
    if kind == "Cylinder":
        return trimesh.creation.cylinder(radius=float(shape.radius), height=2.0 * float(shape.halfLength),
                                         sections=24)
    if kind == "Box":
        return trimesh.creation.box(extents=2.0 * np.asarray(shape.halfSide, dtype=float))
    if kind == "Sphere":
        return trimesh.creation.icosphere(subdivisions=2, radius=float(shape.radius))
    return None
