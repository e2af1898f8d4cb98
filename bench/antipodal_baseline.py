"""An antipodal grasp sampler of the Dex-Net / GPD kind: the baseline isf's grasps are judged
against.

:func:`plan_antipodal` samples contact pairs on the object's surface whose line lies inside both
friction cones, places a parallel gripper on each pair (its pads on the two contacts, opened to
the pair's width, turned about the pair's line to a collision-free approach), and ranks the
grasps by how well the normals align with the line and how near the grasp centre lies to the
object's centre of mass:

1. First contact ``p1`` (outward normal ``n1``): a random surface point. The gripper closes along
   a random direction ``a`` inside the friction cone of ``p1`` (angle to ``-n1`` at most
   ``atan(friction)``).
2. Second contact ``p2``: among the surface points within ``line_tolerance`` of the line
   ``p1 + t a`` (``t`` between ``min_width`` and the gripper's opening), the nearest along it
   whose outward normal ``n2`` has ``-a`` inside its friction cone (angle of ``a`` to ``n2`` at
   most ``atan(friction)``).
3. The gripper: its pads' closing axis (from one pad's centre to the other's) on ``a``, the
   pads' centre on the pair's midpoint, the fingers at the pair's width (the single actuated
   joint solved by bisection), the approach axis turned about ``a`` through ``turns`` angles;
   the first collision-free turn (:class:`isf.collision.checker.CollisionChecker`) is kept.
4. Ranking, lower first: ``(angle1 + angle2) / (2 atan(friction)) + |centre - com| / radius``
   (``angle`` the two cone angles, ``com`` and ``radius`` from
   :func:`isf.quality.object_properties`).

Frames: ``T_object_gripper`` is the gripper frame (URDF root link) in the object frame, as in
:func:`isf.plan`.

Usage (a quick look): ``python bench/antipodal_baseline.py OBJECT [--gripper flat-parallel]``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

import isf
from isf.collision.checker import CollisionChecker
from isf.quality import object_properties

__all__ = ["AntipodalGrasp", "plan_antipodal"]


@dataclass(frozen=True)
class AntipodalGrasp:
    """One baseline grasp.

    Attributes:
        T_object_gripper: the gripper frame in the object frame, (4, 4).
        joints: joint values by name (the actuated joint at the pair's width), metres/radians.
        q: the same as the gripper's joint vector, (n_joints,).
        contacts: the two contact points, object frame, (2, 3), metres.
        width: their distance, metres.
        cone_angles: angle of the closing line to each contact's inward normal, radians, (2,).
        com_distance: distance from the grasp centre to the centre of mass, metres.
        score: the ranking score (lower first, see the module docstring).
    """

    T_object_gripper: np.ndarray
    joints: dict[str, float]
    q: np.ndarray
    contacts: np.ndarray
    width: float
    cone_angles: np.ndarray
    com_distance: float
    score: float


class _PadGeometry:
    """The two pads of a parallel gripper: closing axis, centre and width per joint value."""

    def __init__(self, gripper: isf.Gripper):
        if gripper.n_joints != 1 or len(gripper.surfaces) != 2:
            raise isf.InvalidInputError(
                f"the antipodal baseline needs a parallel gripper (one actuated joint, two contact "
                f"surfaces); {gripper.name} has {gripper.n_joints} joints and "
                f"{len(gripper.surfaces)} surfaces")
        self.gripper = gripper
        lower, upper = gripper.model.lowerPositionLimit[0], gripper.model.upperPositionLimit[0]
        self.lower, self.upper = float(lower), float(upper)
        self.widths = [self.width(self.lower), self.width(self.upper)]

    def pads(self, q: float) -> tuple[np.ndarray, np.ndarray]:
        points, _ = self.gripper.contact_points(np.array([q]))
        s = self.gripper.point_surface
        return points[s == 0].mean(axis=0), points[s == 1].mean(axis=0)

    def width(self, q: float) -> float:
        a, b = self.pads(q)
        return float(np.linalg.norm(b - a))

    def joint_for(self, width: float) -> float | None:
        """The joint value whose pads are ``width`` apart (bisection), None beyond the range."""
        lo, hi = self.lower, self.upper
        w_lo, w_hi = self.widths
        if not min(w_lo, w_hi) <= width <= max(w_lo, w_hi):
            return None
        rising = w_hi > w_lo
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if (self.width(mid) < width) == rising:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)


def _frame(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Orthonormal basis (3, 3) as columns: ``first``, ``second`` made orthogonal, their cross."""
    e1 = first / np.linalg.norm(first)
    e2 = second - (second @ e1) * e1
    e2 /= np.linalg.norm(e2)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=1)


def plan_antipodal(gripper: isf.Gripper | str, surface: isf.ObjectSurface, n_grasps: int = 20,
                   seed: int = 0, friction: float = 0.5, *, candidates: int = 400,
                   turns: int = 8, min_width: float = 0.004,
                   line_tolerance: float | None = None) -> list[AntipodalGrasp]:
    """Up to ``n_grasps`` collision-free antipodal grasps of ``surface``, best first (see the
    module docstring); ``candidates`` first contacts are drawn with ``seed``."""
    gripper = gripper if isinstance(gripper, isf.Gripper) else isf.load_gripper(gripper)
    pads = _PadGeometry(gripper)
    checker = CollisionChecker(gripper, surface)
    properties = object_properties(surface)
    rng = np.random.default_rng(seed)
    points, normals = surface.points, surface.normals
    tree = cKDTree(points)
    tolerance = 1.5 * surface.spacing if line_tolerance is None else line_tolerance
    cone = np.arctan(friction)
    max_width = max(pads.widths)
    approach = gripper.approach_root
    found = []
    for i in rng.choice(len(points), size=min(candidates, len(points)), replace=False):
        p1, inward = points[i], -normals[i]
        axis = _inside_cone(inward, cone, rng)
        pair = _second_contact(p1, axis, points, normals, tree, tolerance, min_width, max_width,
                               cone)
        if pair is None:
            continue
        j, width = pair
        q = pads.joint_for(width)
        if q is None:
            continue
        a, b = pads.pads(q)
        centre_g = 0.5 * (a + b)
        closing = _frame(b - a, approach)  # gripper: closing axis, approach, their cross
        p2 = points[j]
        centre = 0.5 * (p1 + p2)
        line = (p2 - p1) / np.linalg.norm(p2 - p1)
        angles = np.array([np.arccos(np.clip(line @ inward, -1, 1)),
                           np.arccos(np.clip(line @ normals[j], -1, 1))])
        for turn in range(turns):
            spin = 2.0 * np.pi * (turn + rng.random()) / turns
            side = _frame(line, np.cross(line, _any_perpendicular(line)))
            way = np.cos(spin) * side[:, 1] + np.sin(spin) * side[:, 2]
            R = _frame(line, way) @ closing.T
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = R, centre - R @ centre_g
            if checker.check(T, np.array([q])).collision_free:
                com_distance = float(np.linalg.norm(centre - properties.center_of_mass))
                score = angles.sum() / (2 * cone) + com_distance / properties.radius
                found.append(AntipodalGrasp(T, gripper.joints(np.array([q])), np.array([q]),
                                            np.stack([p1, p2]), width, angles, com_distance,
                                            float(score)))
                break
    found.sort(key=lambda g: g.score)
    return found[:n_grasps]


def _any_perpendicular(v: np.ndarray) -> np.ndarray:
    axis = np.eye(3)[np.argmin(np.abs(v))]
    return np.cross(v, axis)


def _inside_cone(direction: np.ndarray, cone: float, rng: np.random.Generator) -> np.ndarray:
    """A random unit direction within ``cone`` radians of the unit ``direction``."""
    basis = _frame(direction, _any_perpendicular(direction))
    tilt, spin = cone * np.sqrt(rng.random()), 2 * np.pi * rng.random()
    return (np.cos(tilt) * basis[:, 0] + np.sin(tilt) * (np.cos(spin) * basis[:, 1]
                                                          + np.sin(spin) * basis[:, 2]))


def _second_contact(p1, axis, points, normals, tree, tolerance, min_width, max_width, cone):
    """The second contact along ``p1 + t axis`` (see the module docstring): (index, width), or
    None."""
    mid = p1 + 0.5 * max_width * axis
    near = np.array(tree.query_ball_point(mid, 0.5 * max_width + tolerance), dtype=int)
    if not len(near):
        return None
    offsets = points[near] - p1
    along = offsets @ axis
    off_line = np.linalg.norm(offsets - np.outer(along, axis), axis=1)
    ok = (along >= min_width) & (along <= max_width) & (off_line <= tolerance)
    ok &= normals[near] @ axis >= np.cos(cone)
    if not ok.any():
        return None
    k = near[ok][np.argmin(along[ok])]
    # the pair must not pass through material: nothing facing the other way nearer on the line
    blocked = (along < along[ok].min()) & (along >= min_width) & (off_line <= tolerance) & (
        normals[near] @ axis > 0.3)
    if blocked.any():
        return None
    return int(k), float(np.linalg.norm(points[k] - p1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("object")
    parser.add_argument("--gripper", default="flat-parallel")
    parser.add_argument("--grasps", type=int, default=5)
    parser.add_argument("--friction", type=float, default=0.5)
    args = parser.parse_args()
    surface = isf.load_object(args.object)
    for g in plan_antipodal(args.gripper, surface, args.grasps, friction=args.friction):
        print(f"width {g.width * 1e3:.1f} mm  angles {np.degrees(g.cone_angles).round(1)} deg  "
              f"com {g.com_distance * 1e3:.1f} mm  score {g.score:.3f}  joints {g.joints}")


if __name__ == "__main__":
    main()
