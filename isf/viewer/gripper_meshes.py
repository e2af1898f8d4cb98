"""The gripper's own link meshes posed at joint values, read by yourdfpy: what ``isf show``
draws and ``isf export`` writes.

Frames: a part's vertices are in the part's own frame (its ``<collision>`` or ``<visual>``
element's frame, the element's ``<origin>`` and mesh scale applied by yourdfpy);
``T_gripper_part`` is that frame's pose in the gripper frame (the URDF root link) at given
joint values; ``T_object_gripper`` places the gripper in the object frame, as in the plan file.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from ..exceptions import GripperDescriptionError, InvalidInputError
from ..gripper.mesh_paths import resolve_mesh_path
from ..gripper.yourdfpy_reading import read_urdf

__all__ = ["GEOMETRIES", "GripperMeshes", "MeshPart"]

GEOMETRIES = ("collision", "visual")
"""Which elements of the URDF's links to draw: ``collision`` (what isf checks) or ``visual``."""


@dataclass(frozen=True, eq=False)
class MeshPart:
    """One geometry element of a link.

    Attributes:
        name: the element's key in yourdfpy's scene (its URDF name, else a generated one).
        link: the link that carries it.
        vertices: (V, 3) in the part's own frame, metres.
        faces: (F, 3) vertex indices.
    """

    name: str
    link: str
    vertices: np.ndarray
    faces: np.ndarray


class GripperMeshes:
    """A URDF's link meshes and their poses at any joint values (yourdfpy's scene graph).

    Args:
        urdf_path: the gripper's URDF.
        geometry: ``"collision"`` or ``"visual"`` (see ``GEOMETRIES``).
        package_dirs: optional ``{package: folder}`` map for ``package://`` mesh paths.

    Raises:
        InvalidInputError: ``geometry`` is not one of ``GEOMETRIES``.
        GripperDescriptionError: yourdfpy cannot read the URDF, or it has no such geometry.
    """

    def __init__(self, urdf_path: str | Path, geometry: str = "collision",
                 package_dirs: Mapping[str, str | Path] | None = None):
        if geometry not in GEOMETRIES:
            raise InvalidInputError(f"geometry {geometry!r}: choose one of {', '.join(GEOMETRIES)}")
        path = Path(urdf_path)
        urdf_dir = path.parent

        def find(fname: str) -> str:
            return str(resolve_mesh_path(fname, urdf_dir, package_dirs))

        collision = geometry == "collision"
        try:
            self._urdf = read_urdf(
                path, build_scene_graph=not collision, load_meshes=not collision,
                build_collision_scene_graph=collision, load_collision_meshes=collision,
                force_collision_mesh=False, filename_handler=find)
        except Exception as exc:  # yourdfpy raises many kinds on a bad file
            raise GripperDescriptionError(str(path), [
                f"yourdfpy cannot read it ({type(exc).__name__}: {exc}): check the URDF with "
                "'isf inspect'"]) from exc
        self._scene = self._urdf.collision_scene if collision else self._urdf.scene
        if self._scene is None or not self._scene.geometry:
            raise GripperDescriptionError(str(path), [
                f"no {geometry} geometry to draw: choose another of {', '.join(GEOMETRIES)}"])
        graph = self._scene.graph
        parts = []
        for node in graph.nodes_geometry:
            _, key = graph[node]
            mesh = self._scene.geometry[key]
            if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
                continue
            parts.append(MeshPart(node, graph.transforms.parents[node],
                                  np.asarray(mesh.vertices, dtype=float),
                                  np.asarray(mesh.faces, dtype=np.int64)))
        self.parts: tuple[MeshPart, ...] = tuple(parts)
        """Every geometry element with triangles, in the scene graph's order."""
        self.joint_names: tuple[str, ...] = tuple(self._urdf.actuated_joint_names)
        """The actuated joints (mimic joints follow them), as the plan file names them."""
        self.root_link: str = self._urdf.base_link
        """The URDF's root link, whose frame is the gripper frame."""

    def part_poses(self, joints: Mapping[str, float]) -> np.ndarray:
        """``T_gripper_part`` of every part at ``joints`` (actuated joints by name, metres or
        radians; missing ones at 0), (P, 4, 4).

        Raises:
            InvalidInputError: a joint name the URDF does not actuate.
        """
        unknown = sorted(set(joints) - set(self.joint_names))
        if unknown:
            raise InvalidInputError(
                f"joints {unknown} are not actuated joints of {self._urdf.robot.name!r} "
                f"({', '.join(self.joint_names)}): pass the gripper the plan was made with")
        self._urdf.update_cfg({name: float(value) for name, value in joints.items()})
        graph = self._scene.graph
        return np.stack([graph.get(p.name, frame_from=self.root_link)[0] for p in self.parts])

    def posed_mesh(self, joints: Mapping[str, float],
                   T_object_gripper: np.ndarray | None = None) -> trimesh.Trimesh:
        """Every part at ``joints`` as one mesh, in the object frame when ``T_object_gripper``
        (4, 4) is given, else in the gripper frame."""
        T = self.part_poses(joints)
        if T_object_gripper is not None:
            T = np.asarray(T_object_gripper, dtype=float) @ T
        meshes = [trimesh.Trimesh(p.vertices @ Tp[:3, :3].T + Tp[:3, 3], p.faces, process=False)
                  for p, Tp in zip(self.parts, T)]
        return trimesh.util.concatenate(meshes)
