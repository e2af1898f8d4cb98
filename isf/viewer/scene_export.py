"""``isf export``: the object and the gripper at one grasp as one mesh scene file.

Frames: the scene's world frame is the plan's object frame (for a scene plan, the scene
frame). In a ``.glb`` the gripper is a node ``gripper`` at ``T_object_gripper`` whose children
are its link meshes (named as yourdfpy names the URDF elements) at ``T_gripper_part``; the
object is the node ``object``. ``.ply`` and ``.obj`` hold the same triangles flattened into the
object frame (``.ply``: one mesh, object first; ``.obj``: one group per node). Lengths in metres.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from ..exceptions import InvalidInputError
from ..output_files import write_atomically
from ..registration.preview import check_export_path
from .gripper_meshes import GripperMeshes
from .plan_file import PlanSources

__all__ = ["OBJECT_COLOUR", "export_grasp", "grasp_scene", "gripper_colour"]

OBJECT_COLOUR = (200, 191, 168, 255)
"""RGBA of the object's faces or points."""


def gripper_colour(grasp: dict) -> tuple[int, int, int, int]:
    """RGBA of the gripper: blue for a valid grasp, orange collision-free, red colliding."""
    if grasp.get("valid"):
        return (74, 120, 194, 255)
    return (224, 160, 48, 255) if grasp["collision_free"] else (208, 48, 48, 255)


def grasp_scene(sources: PlanSources, meshes: GripperMeshes, grasp: dict) -> trimesh.Scene:
    """The object and the gripper at ``grasp`` (a plan file's grasp record) as a trimesh scene
    (see the module docstring for its frames)."""
    scene = trimesh.Scene(base_frame="world")
    surface = sources.surface
    if surface.is_mesh:
        obj = trimesh.Trimesh(surface.mesh_vertices, surface.mesh_faces, process=False)
        obj.visual.face_colors = OBJECT_COLOUR
    else:
        obj = trimesh.PointCloud(surface.points, colors=np.tile(OBJECT_COLOUR, (surface.n_points, 1)))
    scene.add_geometry(obj, node_name="object", geom_name="object")
    T_object_gripper = np.asarray(grasp["T_object_gripper"], dtype=float)
    scene.graph.update(frame_from="world", frame_to="gripper", matrix=T_object_gripper)
    poses = meshes.part_poses({k: float(v) for k, v in grasp["joints"].items()})
    colour = gripper_colour(grasp)
    for part, T in zip(meshes.parts, poses):
        mesh = trimesh.Trimesh(part.vertices, part.faces, process=False)
        mesh.visual.face_colors = colour
        scene.add_geometry(mesh, node_name=part.name, geom_name=part.name,
                           parent_node_name="gripper", transform=T)
    return scene


def export_grasp(sources: PlanSources, grasp: dict, out: str | Path, *,
                 geometry: str = "collision") -> Path:
    """Write the object and the gripper at ``grasp`` to ``out`` (``.glb``, ``.ply`` or ``.obj``),
    atomically, with the user's umask.

    Raises:
        OutputFileError: the suffix is not one of ``.glb``, ``.ply``, ``.obj``
            (``isf.registration.preview.EXPORT_FORMATS``), or ``out`` cannot be written
            (checked before any work).
        InvalidInputError: a point-cloud object (or scene) to a format other than ``.glb``.
        GripperDescriptionError: yourdfpy cannot read the gripper's URDF.
    """
    path = check_export_path(out)
    kind = path.suffix.lower().lstrip(".")
    if not sources.surface.is_mesh and kind != "glb":
        raise InvalidInputError(f"the object is a point cloud, which a .{kind} mesh cannot hold "
                                "beside triangles: name a .glb file")
    meshes = GripperMeshes(sources.gripper.urdf_path, geometry)
    scene = grasp_scene(sources, meshes, grasp)
    if kind == "ply":
        data = trimesh.util.concatenate(scene.dump()).export(file_type="ply")
    else:
        data = scene.export(file_type=kind)
    return write_atomically(path, data if isinstance(data, bytes) else data.encode("utf-8"),
                            "export file")
