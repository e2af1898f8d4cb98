"""Does the closing reach the contact surfaces first? Links that would take the grip.

A gripper closes its fingers until something stops them. When a link that moves with a closing
finger but carries no contact surface (a Robotiq 2F-85's inner knuckle) sits deeper in the
object at the planned joints than a contact surface it closes with, the closing fingers meet
the object there first. Where stopping that link stops every closing joint that moves the
contact surface (the Robotiq's one actuated joint drives both fingers and their knuckles
through its linkage), that link takes the squeeze, and the contact surface, whose contacts
the quality metrics count, presses little or not at all. A link that leaves one of the
contact surface's closing joints free does not: a hand's proximal phalanx that meets the
object first stalls its own joint, and the joints beyond it still press the fingertip. The
palm and other links that no closing joint moves do not close onto the object and are not
counted (they touch or they do not, as the collision check says).

Depths are those of the collision check (:attr:`isf.collision.CollisionReport.link_depths`,
metres, 0 for a link outside the object), which accepts links up to its tolerance inside; a
link counts as deeper when it is deeper by more than :data:`OBSTRUCTION_MARGIN`, the least
error the check allows its predicted depths (0.1 mm plus half the distance to the exactly
evaluated centre of its patch, :mod:`isf.collision.checker`), so that a link level with its
contact surface (its depth read a few micrometres deeper) does not count.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..gripper.model import Gripper

__all__ = ["OBSTRUCTION_MARGIN", "closing_obstructions"]

OBSTRUCTION_MARGIN = 1e-4
"""Depth, metres, by which a link must lie deeper in the object than a contact surface it can
stop to obstruct the closing (:func:`closing_obstructions`)."""


def closing_obstructions(gripper: Gripper, q: np.ndarray, link_depths: Mapping[str, float], *,
                         margin: float = OBSTRUCTION_MARGIN) -> tuple[str, ...]:
    """The links that would take the grip from the contact surfaces as the fingers close.

    A link obstructs the closing when it carries no contact surface and lies deeper in the
    object, by more than ``margin``, than the contact-surface links it can stop: those whose
    every closing joint also moves it (:meth:`isf.Gripper.closing_joints_of_links` at ``q``),
    so that once it meets the object none of their closing joints can move them further.

    Args:
        gripper: the gripper.
        q: the grasp's joints (n_joints,), metres or radians.
        link_depths: how deep each link sits in the object, metres, by link name (links left
            out count as 0).
        margin: how much deeper than the contact surfaces a link must lie, metres.

    Returns:
        the obstructing links' names, in the order of ``link_depths``; empty when every
        contact surface lies at least as deep (within ``margin``) as the links that can stop it.
    """
    moved_by = gripper.closing_joints_of_links(q)
    contact_links = gripper.contact_links
    obstructing = []
    for link, depth in link_depths.items():
        joints = moved_by.get(link, frozenset())
        if link in contact_links or not joints:
            continue
        stopped = [c for c in contact_links if moved_by.get(c) and moved_by[c] <= joints]
        if stopped and depth > max(link_depths.get(c, 0.0) for c in stopped) + margin:
            obstructing.append(link)
    return tuple(obstructing)
