"""Optional live view of the simulator (``sctd sim --view``): Meshcat, else Viser.

Neither package is a dependency of sctd; the view draws the arm as spheres at its
joint origins and the scene's objects as small boxes (the URDF carries no meshes), and
is updated at about 30 Hz from the simulation loop.
"""

from __future__ import annotations

import importlib.util
from typing import Any

import numpy as np
import pinocchio as pin


class ViewerUnavailable(RuntimeError):
    """No supported viewer package is installed."""


def open_viewer() -> Any:
    """A :class:`MeshcatView` or :class:`ViserView`, whichever package is installed.

    Raises
    ------
    ViewerUnavailable
        Neither ``meshcat`` nor ``viser`` can be imported.
    """
    if importlib.util.find_spec("meshcat") is not None:
        return MeshcatView()
    if importlib.util.find_spec("viser") is not None:
        return ViserView()
    raise ViewerUnavailable("needs the meshcat or viser package (pip install meshcat, or "
                            "pip install viser); neither is installed")


def _joint_points(sim) -> list[np.ndarray]:
    arm = sim.arm.arm
    data = arm.model.createData()
    pin.framesForwardKinematics(arm.model, data, sim.arm.dynamics.q)
    pts = [data.oMi[i].translation.copy() for i in range(arm.model.njoints)]
    pts.append(data.oMf[arm.ee_frame_id].translation.copy())
    return pts


class MeshcatView:
    """Meshcat (browser) view; prints its URL."""

    def __init__(self) -> None:
        import meshcat

        self.vis = meshcat.Visualizer()
        print(f"sctd sim: view at {self.vis.url()}", flush=True)

    def setup(self, sim) -> None:
        import meshcat.geometry as g

        for k in range(len(_joint_points(sim))):
            self.vis[f"arm/{k}"].set_object(g.Sphere(0.04), g.MeshLambertMaterial(color=0xdddddd))
        for name in sim.objects():
            self.vis[f"objects/{name}"].set_object(g.Box([0.06, 0.06, 0.02]),
                                                   g.MeshLambertMaterial(color=0x3366cc))
        self.update(sim)

    def update(self, sim) -> None:
        from sctd import se3

        for k, p in enumerate(_joint_points(sim)):
            T = np.eye(4)
            T[:3, 3] = p
            self.vis[f"arm/{k}"].set_transform(T)
        for name, pose in sim.objects().items():
            self.vis[f"objects/{name}"].set_transform(se3.transform_from_pose(pose))


class ViserView:
    """Viser (browser) view on its default port."""

    def __init__(self) -> None:
        import viser

        self.server = viser.ViserServer()
        self.handles: dict[str, Any] = {}

    def setup(self, sim) -> None:
        scene = self.server.scene
        for k, p in enumerate(_joint_points(sim)):
            self.handles[f"arm/{k}"] = scene.add_icosphere(f"/arm/{k}", radius=0.04, position=tuple(p))
        for name, pose in sim.objects().items():
            self.handles[name] = scene.add_box(f"/objects/{name}", dimensions=(0.06, 0.06, 0.02),
                                               position=tuple(pose[:3]))

    def update(self, sim) -> None:
        for k, p in enumerate(_joint_points(sim)):
            self.handles[f"arm/{k}"].position = tuple(p)
        for name, pose in sim.objects().items():
            h = self.handles[name]
            h.position = tuple(pose[:3])
            h.wxyz = (pose[6], pose[3], pose[4], pose[5])
