"""Small grippers and objects built in code for the core tests (no files)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from isf.gripper.model import ContactSurface, Gripper
from isf.object.surface import ObjectSurface

PARALLEL_XML = """<robot name="parallel">
  <link name="palm"/><link name="left"/><link name="right"/>
  <joint name="left_joint" type="prismatic"><parent link="palm"/><child link="left"/>
    <axis xyz="0 -1 0"/><limit lower="{lo}" upper="{hi}" effort="1" velocity="1"/></joint>
  <joint name="right_joint" type="prismatic"><parent link="palm"/><child link="right"/>
    <axis xyz="0 1 0"/><limit lower="{lo}" upper="{hi}" effort="1" velocity="1"/>
    <mimic joint="left_joint" multiplier="1" offset="0"/></joint>
</robot>"""


def parallel_gripper(left, right, *, lower=0.0, upper=0.04, q_initial=0.02) -> Gripper:
    """A 1-DoF parallel gripper: joint q moves the left finger to -y and the right to +y.

    Args:
        left, right: (points, normals) of each finger's contact surface in its link
            frame, each (N, 3); the link frames coincide with the palm at q = 0.
    """
    model = pin.buildModelFromXML(PARALLEL_XML.format(lo=lower, hi=upper), mimic=True)
    surfaces = (
        ContactSurface("left", "left", *left, area=1e-4),
        ContactSurface("right", "right", *right, area=1e-4),
    )
    return Gripper(name="parallel", model=model, surfaces=surfaces, q_initial=np.array([q_initial]))


def bumpy_height(x, y):
    """A smooth, non-symmetric height field z = f(x, y) and its gradient (metres)."""
    z = 0.004 * np.sin(60 * x + 0.3) * np.cos(45 * y) + 0.002 * np.sin(90 * y + 1.0) + 3 * x * y
    dzdx = 0.24 * np.cos(60 * x + 0.3) * np.cos(45 * y) + 3 * y
    dzdy = -0.18 * np.sin(60 * x + 0.3) * np.sin(45 * y) + 0.18 * np.cos(90 * y + 1.0) + 3 * x
    return z, dzdx, dzdy


def bumpy_patch(x, y, *, up: bool = True):
    """Points on the bumpy surface at (x, y) and unit normals (+z side if ``up``)."""
    z, zx, zy = bumpy_height(x, y)
    normals = np.c_[-zx, -zy, np.ones_like(x)]
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    return np.c_[x, y, z], normals if up else -normals


def bumpy_object(n=6000, half=0.04, seed=0) -> ObjectSurface:
    """Dense samples of the bumpy surface over a square of side ``2 half``, normals +z."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-half, half, (2, n))
    points, normals = bumpy_patch(x, y)
    return ObjectSurface(points, normals, spacing=2 * half / np.sqrt(n), name="bumpy")


def cylinder_object(radius, length=0.06, n=6000, seed=0) -> ObjectSurface:
    """Samples of a cylinder's side, axis x through the origin, outward normals."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 2 * np.pi, n)
    x = rng.uniform(-length / 2, length / 2, n)
    points = np.c_[x, radius * np.cos(a), radius * np.sin(a)]
    normals = np.c_[np.zeros(n), np.cos(a), np.sin(a)]
    return ObjectSurface(points, normals, spacing=np.sqrt(2 * np.pi * radius * length / n))


def random_rotation(rng, angle):
    """A rotation by ``angle`` radians about a random axis, (3, 3)."""
    from isf.se3 import exp_so3

    axis = rng.normal(size=3)
    return exp_so3(angle * axis / np.linalg.norm(axis))


def sphere_contacts(rng, low: int, high: int, radius: float = 0.03):
    """``low`` to ``high - 1`` point contacts at random on a sphere of ``radius`` (m) about the
    origin, pushing inwards, and object properties whose centre of mass lies a few mm off the
    origin (object radius 5 cm): points (n, 3), inward normals (n, 3), properties."""
    from isf.quality import ObjectProperties

    points = rng.normal(size=(int(rng.integers(low, high)), 3))
    points = radius * points / np.linalg.norm(points, axis=1, keepdims=True)
    return points, -points, ObjectProperties(rng.normal(scale=0.008, size=3), 0.05)
