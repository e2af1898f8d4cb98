"""Conformance kit for sampler plugins, plus small canonical problems.

Plugin authors run :func:`check_sampler` in their own tests::

    from isf.testing import check_sampler
    from my_plugin import MySampler

    def test_conformance():
        check_sampler(MySampler)

It raises :class:`AssertionError` naming the first broken rule of the
sampler contract (see ``docs/samplers.md``).
"""

from __future__ import annotations

import copy
import json
import random
import re

import numpy as np
import pinocchio as pin

from .gripper.model import ContactSurface, Gripper
from .object.surface import ObjectSurface
from .samplers.base import NO_CONTACT_ERROR, Outcome, Proposal, Sampler

__all__ = ["canonical_gripper", "canonical_object", "check_sampler"]

# A parallel-jaw gripper: root "base_link", a tilted fixed "palm", one prismatic
# jaw and its mimic twin. Finger joint value = half the jaw opening, metres.
_GRIPPER_URDF = """<?xml version="1.0"?>
<robot name="isf_test_gripper">
  <link name="base_link"/>
  <link name="palm"/>
  <link name="left_finger"/>
  <link name="right_finger"/>
  <joint name="palm_mount" type="fixed">
    <parent link="base_link"/><child link="palm"/>
    <origin xyz="0.01 0 0.02" rpy="0.3 0 1.5707963267948966"/>
  </joint>
  <joint name="left_finger_joint" type="prismatic">
    <parent link="palm"/><child link="left_finger"/>
    <origin xyz="0 0 0.04"/><axis xyz="0 1 0"/>
    <limit lower="0.0" upper="0.04" effort="10" velocity="0.1"/>
  </joint>
  <joint name="right_finger_joint" type="prismatic">
    <parent link="palm"/><child link="right_finger"/>
    <origin xyz="0 0 0.04"/><axis xyz="0 1 0"/>
    <limit lower="-0.04" upper="0.0" effort="10" velocity="0.1"/>
    <mimic joint="left_finger_joint" multiplier="-1" offset="0"/>
  </joint>
</robot>
"""


def _pad(name: str, link: str, side: float, n_side: int = 6) -> ContactSurface:
    """A 2 cm x 2 cm square pad in the finger's x-z plane, normal ``(0, side, 0)``."""
    x, z = np.meshgrid(np.linspace(-0.01, 0.01, n_side), np.linspace(0.0, 0.02, n_side))
    points = np.column_stack([x.ravel(), np.zeros(x.size), z.ravel()])
    normals = np.tile([0.0, side, 0.0], (len(points), 1))
    return ContactSurface(name=name, link=link, points=points, normals=normals, area=4e-4)


def canonical_gripper(
    *, palm_link: str | None = "palm", approach: tuple[float, float, float] | None = (0, 0, 1)
) -> Gripper:
    """A small parallel-jaw gripper built in code (no files).

    The root link is ``base_link``; ``palm`` is fixed to it with an offset and
    a tilt; two 2 cm pads face each other, 4 cm (``q_initial = 0.02``) apart,
    along the palm's y axis, 4-6 cm along its z axis.

    Args:
        palm_link: the declared palm link (``"palm"``, ``"base_link"`` or None).
        approach: approach direction in the palm link frame, or None.

    Returns:
        the gripper; one joint (``left_finger_joint``, metres, limits [0, 0.04]).
    """
    model = pin.buildModelFromXML(_GRIPPER_URDF, mimic=True)
    return Gripper(
        name="isf_test_gripper",
        model=model,
        surfaces=(_pad("left", "left_finger", -1.0), _pad("right", "right_finger", 1.0)),
        q_initial=np.array([0.02]),
        palm_link=palm_link,
        approach=None if approach is None else np.asarray(approach, dtype=float),
    )


def canonical_object(kind: str = "box", n_points: int = 400) -> ObjectSurface:
    """A small object surface sampled (deterministically) from a trimesh primitive.

    Args:
        kind: ``"box"`` (6 x 4 x 3 cm, centred) or ``"sphere"`` (radius 3 cm, centred).
        n_points: number of surface points.

    Returns:
        the object surface, object frame = the primitive's frame, metres.

    Raises:
        ValueError: for an unknown ``kind``.
    """
    import trimesh  # heavy import, only when asked for

    if kind == "box":
        mesh = trimesh.creation.box(extents=(0.06, 0.04, 0.03))
    elif kind == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.03)
    else:
        raise ValueError(f"unknown canonical object {kind!r}; use 'box' or 'sphere'")
    points, face = trimesh.sample.sample_surface(mesh, n_points, seed=0)
    return ObjectSurface(
        points=points,
        normals=mesh.face_normals[face],
        spacing=float(np.sqrt(mesh.area / n_points)),
        name=f"canonical {kind}",
        mesh_vertices=np.asarray(mesh.vertices, dtype=float),
        mesh_faces=np.asarray(mesh.faces),
    )


def _fail(sampler: Sampler, message: str) -> None:
    raise AssertionError(f"sampler {type(sampler).__name__} ({sampler.name!r}): {message}")


def _check_proposals(
    sampler: Sampler, proposals: object, n: int, gripper: Gripper, tol: float = 1e-8
) -> None:
    """Assert the shape and validity rules for one ``propose(n)`` answer."""
    if not isinstance(proposals, list):
        _fail(sampler, f"propose({n}) returned {type(proposals).__name__}; return a list")
    if len(proposals) != n:
        _fail(sampler, f"propose({n}) returned {len(proposals)} proposals; return exactly n")
    for i, p in enumerate(proposals):
        where = f"propose({n})[{i}]"
        if not isinstance(p, Proposal):
            _fail(sampler, f"{where} is {type(p).__name__}; return isf.samplers.Proposal objects")
        T = p.T_object_gripper
        if not np.all(np.isfinite(T)):
            _fail(sampler, f"{where}.T_object_gripper is not finite")
        if not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
            _fail(sampler, f"{where}.T_object_gripper last row is {T[3]}, must be [0, 0, 0, 1]")
        R = T[:3, :3]
        if np.abs(R.T @ R - np.eye(3)).max() > tol:
            _fail(sampler, f"{where}: rotation part is not orthonormal (R^T R != I)")
        if abs(np.linalg.det(R) - 1.0) > tol:
            _fail(sampler, f"{where}: rotation has det {np.linalg.det(R):.6g}; must be +1")
        if p.q is not None:
            if p.q.shape != (gripper.n_joints,) or not np.all(np.isfinite(p.q)):
                _fail(sampler, f"{where}.q must be finite with shape ({gripper.n_joints},)")
            if np.any(p.q < gripper.lower - 1e-12) or np.any(p.q > gripper.upper + 1e-12):
                _fail(sampler, f"{where}.q = {p.q} is outside the joint limits")
        try:
            json.dumps(p.record, allow_nan=False)
        except (TypeError, ValueError) as err:
            _fail(sampler, f"{where}.record is not JSON-serialisable ({err}); use plain types")


def _planner_outcome(proposal: Proposal, i: int, hears_quality: bool) -> Outcome:
    """The ``i``-th of a cycle of the outcomes the planner reports: valid, colliding (its
    contacts touching), collision-free but not touching (``NO_CONTACT_ERROR``); for a sampler
    that hears the quality, the valid ones expected to hold and not in turn."""
    error = 1e-3 * (i + 1)
    if i % 3 == 0:
        holds = (i % 6 == 0) if hears_quality else None
        return Outcome(proposal, error, collision_free=True, valid=True, holds=holds)
    if i % 3 == 1:
        return Outcome(proposal, error, collision_free=False, valid=False)
    return Outcome(proposal, NO_CONTACT_ERROR, collision_free=True, valid=False)


def _run_plan(
    sampler: Sampler, obj: ObjectSurface, gripper: Gripper, seed: int
) -> list[list[Proposal]]:
    """Drive one plan (reset, propose, observe, propose) and check every answer."""
    rng = np.random.default_rng(seed)
    hears_quality = sampler.hears_quality()
    if not isinstance(hears_quality, (bool, np.bool_)):
        _fail(sampler, f"hears_quality() returned {hears_quality!r}; must return True or False")
    sampler.reset(obj, gripper, rng)
    batches = []
    for n in (1, 5):
        proposals = sampler.propose(n, rng)
        _check_proposals(sampler, proposals, n, gripper)
        batches.append(proposals)
        sampler.observe([_planner_outcome(p, i, bool(hears_quality))
                         for i, p in enumerate(proposals)])
    proposals = sampler.propose(3, rng)
    _check_proposals(sampler, proposals, 3, gripper)
    batches.append(proposals)
    return batches


def _same(a: list[list[Proposal]], b: list[list[Proposal]]) -> bool:
    """True when two runs proposed exactly the same poses, joints and records."""
    for pa, pb in zip((p for batch in a for p in batch), (p for batch in b for p in batch)):
        if not np.array_equal(pa.T_object_gripper, pb.T_object_gripper):
            return False
        qa, qb = pa.q, pb.q
        if (qa is None) != (qb is None) or (qa is not None and not np.array_equal(qa, qb)):
            return False
        if json.dumps(pa.record, sort_keys=True) != json.dumps(pb.record, sort_keys=True):
            return False
    return True


def _global_rng_state() -> tuple:
    state = np.random.get_state()  # noqa: NPY002  (numpy's global RNG is what this checks)
    return (state[0], state[1].copy(), *state[2:], random.getstate())


def _states_equal(a: tuple, b: tuple) -> bool:
    return a[0] == b[0] and np.array_equal(a[1], b[1]) and a[2:] == b[2:]


def check_sampler(
    sampler_or_class: Sampler | type[Sampler],
    *,
    gripper: Gripper | None = None,
    obj: ObjectSurface | None = None,
    seed: int = 0,
) -> None:
    """Assert that a sampler follows the sampler contract.

    Checks: ``name`` and ``description`` are set; ``propose(n)`` returns a
    list of exactly ``n`` :class:`Proposal`; each pose is finite with last row
    ``[0, 0, 0, 1]`` and a proper rotation; ``q`` is None or inside the joint
    limits; ``record`` is JSON-serialisable; ``hears_quality()`` returns a bool;
    ``observe`` accepts outcomes of each kind the planner reports (valid, colliding, not
    touching; valid ones expected to hold and not when the sampler hears the quality); two
    fresh instances with the same seed propose identical grasps; ``reset``
    starts a plan afresh; NumPy's and Python's global RNGs are untouched.

    Args:
        sampler_or_class: a Sampler subclass (built with default parameters)
            or a configured instance (copied, never mutated).
        gripper: gripper to plan for; default :func:`canonical_gripper`.
        obj: object to plan on; default :func:`canonical_object`.
        seed: seed of the plans' random generators.

    Raises:
        AssertionError: naming the first rule the sampler breaks.
    """
    if isinstance(sampler_or_class, type):
        if not issubclass(sampler_or_class, Sampler):
            raise AssertionError(f"{sampler_or_class!r} is not a subclass of isf.samplers.Sampler")
        template = sampler_or_class()
    elif isinstance(sampler_or_class, Sampler):
        template = copy.deepcopy(sampler_or_class)
    else:
        raise AssertionError(f"{sampler_or_class!r} is neither a Sampler subclass nor an instance")
    gripper = canonical_gripper() if gripper is None else gripper
    obj = canonical_object() if obj is None else obj

    if not isinstance(template.name, str) or not re.fullmatch(r"[a-z0-9_]+", template.name):
        _fail(template, f"class attribute name={template.name!r} must match [a-z0-9_]+")
    if not isinstance(template.description, str) or not template.description.strip():
        _fail(template, "class attribute description must be a non-empty one-line string")

    before = _global_rng_state()
    first = copy.deepcopy(template)
    run_a = _run_plan(first, obj, gripper, seed)
    run_b = _run_plan(copy.deepcopy(template), obj, gripper, seed)
    run_c = _run_plan(first, obj, gripper, seed)
    if not _states_equal(before, _global_rng_state()):
        _fail(template, "it changed numpy's or Python's global RNG; use only the rng argument")
    if not _same(run_a, run_b):
        _fail(template, "two fresh instances with the same seed proposed different grasps; "
              "draw randomness only from the rng argument")
    if not _same(run_a, run_c):
        _fail(template, "a second plan on the same instance differs from the first with the "
              "same seed; reset() must forget earlier plans")
