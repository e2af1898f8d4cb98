"""Whether an object lies within what a gripper can span: :func:`warn_if_outside_span`.

A gripper closes on an object between its contact surfaces, so it can hold an object only
where some width of the object lies between its smallest and its largest opening. An object
smaller than the smallest opening in every direction, or larger than the largest opening in
every direction, has no grasp at all; the usual cause is a file in millimetres or centimetres
read as metres (a 30 mm part becomes a 30 m one). :func:`isf.plan` warns about it
(:class:`isf.exceptions.ObjectSizeWarning`) and plans anyway.

The gripper's opening at a joint vector is the largest gap between two of its contact surfaces
(the gap of two surfaces: the shortest distance between their points, gripper frame); it is
evaluated at the joint limits and the initial configuration. The object's extents are its
widths along the principal axes of its surface points.
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np

from ..exceptions import ObjectSizeWarning
from ..gripper.model import Gripper
from ..object.surface import ObjectSurface

__all__ = ["Span", "gripper_span", "object_extent", "span_mismatch", "warn_if_outside_span"]


class Span(NamedTuple):
    """A range of lengths, metres: a gripper's openings or an object's extents."""

    smallest: float
    largest: float


def gripper_span(gripper: Gripper) -> Span | None:
    """The smallest and largest opening between the gripper's contact surfaces, metres (see the
    module docstring); None for a gripper with fewer than two contact surfaces."""
    n_surfaces = len(gripper.surfaces)
    if n_surfaces < 2:
        return None
    openings = []
    for q in (gripper.lower, gripper.upper, gripper.q_initial):
        points, _ = gripper.contact_points(q)
        surfaces = [points[gripper.point_surface == k] for k in range(n_surfaces)]
        openings.append(max(
            float(np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=-1).min()))
            for i, a in enumerate(surfaces) for b in surfaces[i + 1:]))
    return Span(min(openings), max(openings))


def object_extent(obj: ObjectSurface) -> Span:
    """The object's smallest and largest width along the principal axes of its points, metres."""
    centred = obj.points - obj.points.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    along = centred @ axes.T
    widths = along.max(axis=0) - along.min(axis=0)
    return Span(float(widths.min()), float(widths.max()))


def _length(metres: float) -> str:
    """A length in the unit that reads best (mm, cm or m)."""
    if metres < 0.01:
        return f"{metres * 1e3:.3g} mm"
    return f"{metres * 1e2:.3g} cm" if metres < 1.0 else f"{metres:.3g} m"


def span_mismatch(gripper: Gripper, obj: ObjectSurface) -> str | None:
    """One line saying why the gripper cannot span the object, or None when it may."""
    span = gripper_span(gripper)
    if span is None or obj.n_points < 2:
        return None
    extent = object_extent(obj)
    if extent.largest < span.smallest:
        what = f"smaller than {gripper.name}'s smallest opening, {_length(span.smallest)}"
    elif extent.smallest > span.largest:
        what = f"larger than {gripper.name}'s largest opening, {_length(span.largest)}"
    else:
        return None
    return (f"object {obj.name} measures {_length(extent.smallest)} to {_length(extent.largest)} "
            f"across, {what}, in every direction, so no grasp can close on it: if its file is "
            "not in metres, pass its units (--units mm or cm; units= in isf.load_object)")


def warn_if_outside_span(gripper: Gripper, obj: ObjectSurface) -> None:
    """Warn (:class:`ObjectSizeWarning`) when :func:`span_mismatch` finds the object out of
    the gripper's reach."""
    message = span_mismatch(gripper, obj)
    if message is not None:
        warnings.warn(ObjectSizeWarning(message), stacklevel=3)
