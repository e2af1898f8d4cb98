"""Grasp quality metrics (isf.quality) against analytic cases worked by hand."""

import numpy as np
import pytest

import isf
from isf.quality import (
    SIX_DIRECTIONS,
    ContactModelConfig,
    Contacts,
    ObjectProperties,
    QualityConfig,
    WrenchSpace,
    contact_wrenches,
    contacts_quality,
    epsilon_quality,
    force_closure,
    grasp_contacts,
    gravity_loads,
)

ORIGIN = np.zeros(3)
DIRECTIONS = np.array(list(SIX_DIRECTIONS.values()))


def antipodal_patches(half_width=0.03, half_side=0.005):
    """Two square pads pressing on the faces x = +-half_width, each as contacts at its four
    corners (y, z) = (+-half_side, +-half_side), normals pointing into the object."""
    points, normals, surface = [], [], []
    for k, side in enumerate((1.0, -1.0)):
        for y in (half_side, -half_side):
            for z in (half_side, -half_side):
                points.append((side * half_width, y, z))
                normals.append((-side, 0.0, 0.0))
                surface.append(k)
    surface = np.array(surface)
    return Contacts(np.array(points), np.array(normals), surface, surface, ("left", "right"))


def test_two_opposing_frictionless_points_are_not_force_closure():
    points = Contacts.from_points([(0.03, 0, 0), (-0.03, 0, 0)], [(-1, 0, 0), (1, 0, 0)])
    wrenches = contact_wrenches(points, 0.0, ORIGIN, 0.03)
    assert not force_closure(wrenches)
    assert epsilon_quality(wrenches) == 0.0
    # with friction two points still turn freely about the line through them
    assert not force_closure(contact_wrenches(points, 0.5, ORIGIN, 0.03))


@pytest.mark.parametrize("edges, corner_factor", [(4, 1.0), (8, np.sqrt(2.0))])
def test_antipodal_patches_epsilon_by_hand(edges, corner_factor):
    """By hand: the weakest wrench of two small pads is a torque about the grasp axis (x). Its
    support: a corner (d, a, a) pushing (-1, mu e) gives torque_x = a mu (e_z - e_y), largest for
    the edge perpendicular to the corner's arm: a mu with the 4 edges +-y, +-z, sqrt(2) a mu
    with 8 edges (the diagonal one); divided by the radius r. Every corner has such an edge, so
    the facet torque_x = that support exists and nothing is nearer (a << d, mu < 1)."""
    mu, a, r = 0.5, 0.005, 0.03
    contacts = antipodal_patches(half_side=a)
    wrenches = contact_wrenches(contacts, mu, ORIGIN, r, edges)
    assert force_closure(wrenches)
    assert epsilon_quality(wrenches) == pytest.approx(corner_factor * mu * a / r, rel=1e-6)
    assert not force_closure(contact_wrenches(contacts, 0.0, ORIGIN, r, edges))  # frictionless


def test_three_point_grasp_on_a_disc():
    """Three fingertips at 120 degrees on a disc's rim (plane z = 0), pushing to its centre."""
    angles = np.radians([90.0, 210.0, 330.0])
    rim = 0.04 * np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], axis=1)
    contacts = Contacts.from_points(rim, -rim)
    # frictionless: no force along z and no torque about it
    assert not force_closure(contact_wrenches(contacts, 0.0, ORIGIN, 0.04))
    assert force_closure(contact_wrenches(contacts, 0.5, ORIGIN, 0.04))
    # by hand: a load along z is held by friction alone, mu times the normal forces: mu F
    F, mu = 12.0, 0.5
    loads = gravity_loads(contacts, mu, ORIGIN, [(0, 0, -1), (0, 0, 1)], F)
    np.testing.assert_allclose(loads, mu * F, rtol=1e-6)


def test_gravity_lp_against_closed_form():
    """Two point contacts on the x axis through the centre of mass, total normal force F: along
    the axis one finger pushes F; across it both press F / 2 and friction holds mu F (the
    pyramid's edges lie along +-y and +-z, so the linearisation is exact there)."""
    F, mu = 10.0, 0.3
    points = Contacts.from_points([(0.03, 0, 0), (-0.03, 0, 0)], [(-1, 0, 0), (1, 0, 0)])
    loads = gravity_loads(points, mu, ORIGIN, DIRECTIONS, F)
    np.testing.assert_allclose(loads, [F, F, mu * F, mu * F, mu * F, mu * F], rtol=1e-6)
    # per finger F each: along the axis one finger still, across both: 2 mu F
    per_finger = gravity_loads(points, mu, ORIGIN, DIRECTIONS, F, per_surface=True)
    np.testing.assert_allclose(per_finger, [F, F, 2 * mu * F, 2 * mu * F, 2 * mu * F, 2 * mu * F],
                               rtol=1e-6)


def test_wrench_space_reach_agrees_with_the_lp():
    """Two methods: where the load's ray leaves the wrench space (qhull) and the LP (HiGHS)."""
    contacts = antipodal_patches()
    for com in ([0, 0, 0], [0, 0, 0.02], [0.01, 0.01, 0.02]):
        space = WrenchSpace(contact_wrenches(contacts, 0.5, np.array(com, float), 0.03))
        reach = 20.0 * space.reach(np.hstack([-DIRECTIONS, np.zeros((6, 3))]))
        lp = gravity_loads(contacts, 0.5, np.array(com, float), DIRECTIONS, 20.0)
        np.testing.assert_allclose(reach, lp, rtol=1e-6)


def test_grasp_far_from_the_centre_of_mass_resists_less():
    contacts = antipodal_patches()
    margins, epsilons = [], []
    for offset in (0.0, 0.02, 0.05, 0.1):  # the centre of mass moves away from the pads
        quality = contacts_quality(contacts, ObjectProperties(np.array([0, 0, offset]), 0.12))
        margins.append(quality.min_margin)
        epsilons.append(quality.epsilon)
    assert all(a > b for a, b in zip(margins, margins[1:]))
    assert all(a > b for a, b in zip(epsilons, epsilons[1:]))


def test_contact_model_of_a_centred_box_grasp():
    """A parallel gripper closed on a box: two patches, each a flat pad in full contact, modelled
    by corner contacts; force closure with friction."""
    gripper = isf.load_gripper("flat-parallel")
    box = isf.open_object("shape:box")
    result = isf.plan(gripper, box, samples=6, seed=0)
    best = result.best
    assert best.valid and best.quality is not None
    contacts = grasp_contacts(gripper, box, best.T_object_gripper, best.q,
                              ContactModelConfig(patch_corners=4, surface_contacts=4))
    assert contacts.patches == 2 and contacts.count == 8
    assert contacts.touching_surfaces == 2
    # the two patches' normals oppose: an antipodal grasp
    left, right = (contacts.normals[contacts.surface == k].mean(axis=0) for k in (0, 1))
    assert left @ right == pytest.approx(-1.0, abs=0.05)
    assert best.quality.force_closure and best.quality.epsilon > 0


def test_quality_config_rejects_bad_values():
    with pytest.raises(isf.InvalidInputError, match="friction"):
        QualityConfig(friction=-0.1)
    with pytest.raises(isf.InvalidInputError, match="mass"):
        QualityConfig(mass=0.0)
    with pytest.raises(isf.InvalidInputError, match="cone_edges"):
        QualityConfig(cone_edges=2)


def test_com_offset_is_the_contacts_centroid_distance_from_the_centre_of_mass():
    """The same two pads, their centroid at the origin: 0 from a centre of mass there; moved
    2 cm along y, 2 cm (the ranking's second criterion, docs/quality.md)."""
    contacts = antipodal_patches()
    centred = contacts_quality(contacts, ObjectProperties(ORIGIN, 0.05))
    shifted = contacts_quality(contacts, ObjectProperties(np.array([0.0, 0.02, 0.0]), 0.05))
    assert centred.com_offset == pytest.approx(0.0, abs=1e-12)
    assert shifted.com_offset == pytest.approx(0.02)
    assert centred.to_dict()["com_offset"] == centred.com_offset
