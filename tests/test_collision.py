"""Collision checks against analytic depths and gaps, and against coal's exact mesh distances.

The gripper (built in code): a palm box under two prismatic fingers. Each finger is a 2 mm pad
box (its inner face is the contact surface) backed by a 1 cm body box, 2 cm wide and 4.5 cm
long. The test pose turns the gripper upside down over a 4 cm cube centred at the origin, so
with palm height ``H`` and joint value ``q`` (object frame):

* palm: x in [-4, 4] cm, |y| <= 1 cm, z in [H, H + 2 cm];
* left pad: x in [q, q + 2 mm], body: x in [q + 2 mm, q + 12 mm]; the right finger mirrors it;
* both fingers: |y| <= 1 cm, z in [H - 4.5 cm, H].
"""

from __future__ import annotations

import time

import numpy as np
import pinocchio as pin
import pytest
import trimesh

from isf.collision import CollisionChecker, CollisionReport, Plane
from isf.exceptions import GripperDescriptionError, InvalidInputError
from isf.gripper import ContactSurface, Gripper, LinkGeometry
from isf.object_surface import ObjectSurface

PAD = 0.002  # pad thickness, m
BODY = 0.01  # finger body thickness, m
LENGTH = 0.045  # finger length, m
CUBE = 0.02  # half edge of the cube object, m

JAW_XML = """<robot name="jaw">
  <link name="palm"/><link name="left"/><link name="right"/>
  <joint name="left_joint" type="prismatic"><parent link="palm"/><child link="left"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.05" effort="1" velocity="1"/></joint>
  <joint name="right_joint" type="prismatic"><parent link="palm"/><child link="right"/>
    <axis xyz="1 0 0"/><limit lower="-0.05" upper="0" effort="1" velocity="1"/>
    <mimic joint="left_joint" multiplier="-1" offset="0"/></joint>
</robot>"""


def _box(link: str, name: str, lo, hi) -> LinkGeometry:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    mesh = trimesh.creation.box(extents=hi - lo)
    mesh.apply_translation((lo + hi) / 2)
    return LinkGeometry(link=link, name=name, vertices=np.asarray(mesh.vertices), faces=np.asarray(mesh.faces))


def _pad_surface(link: str, side: float) -> ContactSurface:
    y, z = np.meshgrid(np.linspace(-0.01, 0.01, 9), np.linspace(0.0, LENGTH, 19))
    points = np.c_[np.zeros(y.size), y.ravel(), z.ravel()]
    normals = np.tile([-side, 0.0, 0.0], (len(points), 1))
    return ContactSurface(name=link, link=link, points=points, normals=normals, area=0.02 * LENGTH)


def jaw_gripper() -> Gripper:
    """The palm + two (pad, body) fingers described in the module docstring."""
    model = pin.buildModelFromXML(JAW_XML, mimic=True)
    geometries = [_box("palm", "palm", (-0.04, -0.01, -0.02), (0.04, 0.01, 0.0))]
    for link, s in (("left", 1.0), ("right", -1.0)):
        for name, a, b in (("pad", 0.0, PAD), ("body", PAD, PAD + BODY)):
            lo, hi = sorted((s * a, s * b))
            geometries.append(_box(link, f"{link}_{name}", (lo, -0.01, 0.0), (hi, 0.01, LENGTH)))
    return Gripper(name="jaw", model=model, surfaces=(_pad_surface("left", 1.0), _pad_surface("right", -1.0)),
                   q_initial=np.array([0.02]), geometries=tuple(geometries))


def mesh_object(mesh: trimesh.Trimesh, n: int = 3000, *, keep_mesh: bool = True) -> ObjectSurface:
    """Surface samples of a trimesh shape with face normals; the mesh too unless ``keep_mesh`` is False."""
    points, face = trimesh.sample.sample_surface(mesh, n, seed=1)
    extra = {"mesh_vertices": np.asarray(mesh.vertices), "mesh_faces": np.asarray(mesh.faces)} if keep_mesh else {}
    return ObjectSurface(points=points, normals=mesh.face_normals[face], spacing=float(np.sqrt(mesh.area / n)),
                         name="test object", **extra)


def pose(height: float, shift=(0.0, 0.0)) -> np.ndarray:
    """Gripper upside down (approach -z) with its palm frame at (shift, height)."""
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[:3, 3] = [shift[0], shift[1], height]
    return T
