"""A test-only pinhole depth camera: ray casting of trimesh meshes with Open3D (a second,
independent implementation of what isf's scenes read), and camera poses that look at a point.

Camera frame: x right, y down, z forward (the depth-image convention isf documents).
"""

from __future__ import annotations

import numpy as np
import trimesh
from _open3d import import_open3d


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """``T_scene_camera`` (4, 4) of a camera at ``eye`` whose optical axis points at ``target``."""
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, eye
    return T


def render_depth(meshes: list[trimesh.Trimesh], T_scene_camera: np.ndarray, *, width: int = 320,
                 height: int = 240, f: float = 300.0, noise: float = 0.0,
                 seed: int = 0) -> tuple[np.ndarray, dict]:
    """The depth image (height, width), metres along the optical axis, 0 where no mesh is hit,
    of scene-frame ``meshes`` seen from ``T_scene_camera``, with Gaussian noise of std
    ``noise`` metres; and its intrinsics ``{"fx", "fy", "cx", "cy"}`` in pixels."""
    o3d = import_open3d()
    scene = o3d.t.geometry.RaycastingScene()
    for mesh in meshes:
        scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                            o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    rays_camera = np.stack([(u - cx) / f, (v - cy) / f, np.ones(u.shape)], axis=-1).reshape(-1, 3)
    directions = rays_camera @ T_scene_camera[:3, :3].T
    origins = np.broadcast_to(T_scene_camera[:3, 3], directions.shape)
    rays = o3d.core.Tensor(np.hstack([origins, directions]).astype(np.float32))
    t_hit = scene.cast_rays(rays)["t_hit"].numpy().astype(float)
    depth = np.where(np.isfinite(t_hit), t_hit, 0.0)  # t along a ray whose z component is 1
    if noise:
        hit = depth > 0
        depth[hit] += np.random.default_rng(seed).normal(0.0, noise, int(hit.sum()))
    return depth.reshape(height, width), {"fx": f, "fy": f, "cx": cx, "cy": cy}


def table_mesh(size: float = 1.2, thickness: float = 0.02) -> trimesh.Trimesh:
    """A table top whose upper face is the plane z = 0."""
    table = trimesh.creation.box((size, size, thickness))
    table.apply_translation((0.0, 0.0, -thickness / 2))
    return table


def box_on_table(extents, centre_xy=(0.0, 0.0)) -> trimesh.Trimesh:
    """A box of ``extents`` (m) standing on z = 0 at ``centre_xy``."""
    box = trimesh.creation.box(extents)
    box.apply_translation((centre_xy[0], centre_xy[1], extents[2] / 2))
    return box
