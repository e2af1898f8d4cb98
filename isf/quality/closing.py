"""Does the closing reach the contact surfaces first? Links that would take the grip.

A gripper closes its fingers until something stops them. When a link that moves with a closing
finger but carries no contact surface (a Robotiq 2F-85's inner knuckle, a hand's middle
phalanx) sits deeper in the object at the planned joints than the contact surfaces it closes
with, the closing fingers meet the object there first: that link takes the squeeze, and the
contact surfaces, whose contacts the quality metrics count, press little or not at all. The
palm and other links that no closing joint moves do not close onto the object and are not
counted (they touch or they do not, as the collision check says).

Depths are those of the collision check (:attr:`isf.collision.CollisionReport.link_depths`,
metres, 0 for a link outside the object), which accepts links up to its tolerance inside; a
link counts as deeper when it is deeper by more than :data:`OBSTRUCTION_MARGIN`, the accuracy
the check's depth estimates are trusted to (:mod:`isf.collision.checker`), so that a link level
with its fingertip (its depth read a few micrometres deeper) does not count.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..gripper.model import Gripper

__all__ = ["OBSTRUCTION_MARGIN", "closing_obstructions"]

OBSTRUCTION_MARGIN = 1e-4
"""Depth, metres, by which a link must lie deeper in the object than the contact surfaces it
closes with to obstruct the closing (:func:`closing_obstructions`)."""


def closing_obstructions(gripper: Gripper, q: np.ndarray, link_depths: Mapping[str, float], *,
                         margin: float = OBSTRUCTION_MARGIN) -> tuple[str, ...]:
    """The links that would take the grip from the contact surfaces as the fingers close.

    A link obstructs the closing when it carries no contact surface, a closing joint moves it
    (:meth:`isf.Gripper.closing_joints_of_links` at ``q``), and it lies deeper in the object,
    by more than ``margin``, than every contact surface's link that one of the same joints
    moves (every contact link when no joint is shared).

    Args:
        gripper: the gripper.
        q: the grasp's joints (n_joints,), metres or radians.
        link_depths: how deep each link sits in the object, metres, by link name (links left
            out count as 0).
        margin: how much deeper than the contact surfaces a link must lie, metres.

    Returns:
        the obstructing links' names, in the order of ``link_depths``; empty when the
        contact surfaces are the deepest links of their fingers (within ``margin``).
    """
    moved_by = gripper.closing_joints_of_links(q)
    contact_links = gripper.contact_links
    obstructing = []
    for link, depth in link_depths.items():
        joints = moved_by.get(link, frozenset())
        if link in contact_links or not joints:
            continue
        partners = [c for c in contact_links if moved_by.get(c, frozenset()) & joints]
        deepest_contact = max(link_depths.get(c, 0.0) for c in partners or contact_links)
        if depth > deepest_contact + margin:
            obstructing.append(link)
    return tuple(obstructing)
