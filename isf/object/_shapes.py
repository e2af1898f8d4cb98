"""Objects isf makes itself: ``shape:NAME`` object specs for demos and tests.

Sizes suit the bundled ``paper-parallel`` gripper (jaw width 1-3 cm) unless the
name says otherwise. Every shape is a closed triangle mesh in metres, centred at
the origin, with its long axis along x.
"""

from __future__ import annotations

import trimesh

__all__ = ["SHAPES", "make_shape"]


def _cylinder() -> trimesh.Trimesh:
    # radius 8 mm fits the paper gripper's groove; 6 cm long
    return trimesh.creation.cylinder(radius=0.008, height=0.06, sections=64).apply_transform(
        trimesh.transformations.rotation_matrix(1.5707963267948966, [0, 1, 0])
    )


def _box() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=[0.05, 0.02, 0.015])


def _sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=4, radius=0.011)


def _capsule() -> trimesh.Trimesh:
    return trimesh.creation.capsule(height=0.05, radius=0.009, count=[48, 24]).apply_transform(
        trimesh.transformations.rotation_matrix(1.5707963267948966, [0, 1, 0])
    )


def _torus() -> trimesh.Trimesh:
    return trimesh.creation.torus(major_radius=0.025, minor_radius=0.007, major_sections=64,
                                  minor_sections=32)


SHAPES = {
    "box": _box,
    "capsule": _capsule,
    "cylinder": _cylinder,
    "sphere": _sphere,
    "torus": _torus,
}
"""Shape name -> factory returning a trimesh.Trimesh in metres."""


def make_shape(name: str) -> trimesh.Trimesh:
    """The mesh of a built-in shape.

    Raises:
        KeyError: unknown name (the message lists the shapes).
    """
    try:
        return SHAPES[name]()
    except KeyError:
        raise KeyError(f"unknown shape {name!r}; shapes are {sorted(SHAPES)}") from None
