"""Grasp quality metrics (isf.quality) against analytic cases worked by hand."""

import numpy as np
import pytest
from _builders import sphere_contacts

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
from isf.quality.gravity import resists_loads
from isf.quality.wrenches import positively_spans

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


def test_squeeze_imbalance_by_hand():
    """The net push of equal squeezes, |sum of the surfaces' unit normals| / surfaces, by hand:
    opposing pads (their four corners each) cancel; two pads whose normals are turned by a
    from opposite push sin(a) per pad; three fingertips 120 degrees apart cancel; three on one
    face against a thumb push (3 - 1) / 4; no contacts push 1."""
    props = ObjectProperties(ORIGIN, 0.05)

    def imbalance(contacts, friction=0.5):
        quality = contacts_quality(contacts, props, QualityConfig(friction=friction))
        return quality.squeeze_imbalance, quality.squeeze_balanced

    assert imbalance(antipodal_patches()) == (pytest.approx(0.0, abs=1e-12), True)
    for degrees, balanced in ((50.0, True), (70.0, False)):  # sin(a / 2) against mu = 0.5
        a = np.radians(degrees)
        turned = Contacts.from_points([(0.03, 0, 0), (-0.03, 0, 0)],
                                      [(-1, 0, 0), (np.cos(a), np.sin(a), 0)])
        value, is_balanced = imbalance(turned)
        assert value == pytest.approx(np.sin(a / 2))
        assert is_balanced is balanced
        assert imbalance(turned, friction=0.6)[1]  # sin(35 degrees) = 0.57 <= 0.6
    angles = 2 * np.pi * np.arange(3) / 3
    ring = np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], axis=1)
    fingertips = Contacts.from_points(0.03 * ring, -ring)
    assert imbalance(fingertips)[0] == pytest.approx(0.0, abs=1e-12)
    assert imbalance(fingertips)[0] > 0.0  # rounding: the unit normals cancel to a few 1e-17
    assert imbalance(fingertips, friction=0.0)[1]  # and count as cancelling without friction
    hand = Contacts.from_points([(-0.03, y, 0) for y in (-0.02, 0.0, 0.02)] + [(0.03, 0, 0)],
                                [(1, 0, 0)] * 3 + [(-1, 0, 0)])
    assert imbalance(hand, friction=0.45) == (pytest.approx(0.5), False)
    assert imbalance(hand, friction=0.55) == (pytest.approx(0.5), True)
    # one surface with several contacts pushes along their mean normal
    pad = Contacts.from_points([(-0.03, 0, 0.01), (-0.03, 0, -0.01), (0.03, 0, 0)],
                               [(1, 0, 0.2), (1, 0, -0.2), (-1, 0, 0)], surface=[0, 0, 1])
    assert imbalance(pad)[0] == pytest.approx(0.0, abs=1e-12)
    empty = Contacts.from_points(np.empty((0, 3)), np.empty((0, 3)))
    assert imbalance(empty) == (1.0, False)
    assert contacts_quality(hand, props).to_dict()["squeeze_imbalance"] == pytest.approx(0.5)


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


def test_resisting_a_load_agrees_with_the_largest_load_of_the_lp():
    """Two methods: the feasibility test (non-negative least squares) says a load is resisted
    exactly where the LP's largest load (HiGHS) reaches it, for loads just below and above."""
    rng = np.random.default_rng(0)
    cases = [(antipodal_patches(), np.array([0.01, 0.0, 0.02]))]
    for _ in range(6):  # random contacts on a sphere of radius 3 cm, pushing inwards
        points = rng.normal(size=(int(rng.integers(2, 6)), 3))
        points = 0.03 * points / np.linalg.norm(points, axis=1, keepdims=True)
        cases.append((Contacts.from_points(points, -points), rng.normal(scale=0.01, size=3)))
    for contacts, com in cases:
        largest = gravity_loads(contacts, 0.5, com, DIRECTIONS, 20.0)
        for factor in (0.98, 1.02):
            for d, load in zip(DIRECTIONS, largest):
                if load == 0.0 and factor < 1:
                    continue
                expected = factor < 1
                got = resists_loads(contacts, 0.5, com, d[None], factor * max(load, 0.1), 20.0,
                                    torque_scale=0.03)[0]
                assert got == expected, (load, factor)


def test_a_failed_load_test_bounds_the_largest_load_of_the_lp():
    """Two methods: a load the feasibility test does not resist bounds the LP's largest load
    (HiGHS) from above by the test's Farkas certificate, at most the load tested; tested 5 %
    above the largest load, the bound is that load (to 1e-8 of it) for most directions."""
    from isf.quality.gravity import _LoadBalance

    tight = tested = 0
    for contacts, com in [(antipodal_patches(), np.array([0.01, 0.0, 0.02])),
                          *_random_contact_sets(seed=5, count=20)]:
        for mu in (0.3, 0.5):
            largest = gravity_loads(contacts, mu, com, DIRECTIONS, 20.0)
            balance = _LoadBalance(contacts, mu, com, 20.0, 4, 0.03)
            for d, load in zip(DIRECTIONS, largest):
                if load < 1e-3:
                    continue
                below = balance.test(d, 0.95 * load)
                assert below.resisted and below.bound == 0.95 * load
                for factor in (1.05, 3.0):
                    above = balance.test(d, factor * load)
                    assert not above.resisted
                    assert load * (1 - 1e-9) <= above.bound <= factor * load
                    if factor == 1.05:
                        tested += 1
                        tight += above.bound <= load * (1 + 1e-8)
    assert tested >= 50 and tight >= 0.75 * tested


def _random_contact_sets(seed: int = 1, count: int = 12):
    """Point contacts on a sphere of radius 3 cm pushing inwards, 1 to 5 of them, and a centre
    of mass near the sphere's centre."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        points = rng.normal(size=(int(rng.integers(1, 6)), 3))
        points = 0.03 * points / np.linalg.norm(points, axis=1, keepdims=True)
        yield Contacts.from_points(points, -points), rng.normal(scale=0.01, size=3)


def test_positive_span_agrees_with_the_hull():
    """Two methods for force closure: the origin inside the hull (qhull) and a strictly
    positive zero combination of wrenches spanning six dimensions (least squares)."""
    seen = set()
    for contacts, com in [(antipodal_patches(), ORIGIN), *_random_contact_sets()]:
        for mu in (0.0, 0.5):
            wrenches = contact_wrenches(contacts, mu, com, 0.03)
            closure = force_closure(wrenches)
            assert positively_spans(wrenches) == closure
            seen.add(closure)
    assert seen == {True, False}


def test_some_load_is_resisted_exactly_where_the_lp_finds_one():
    """Without a bound on the grip the test says whether the LP's largest load is above 0."""
    seen = set()
    for contacts, com in [(antipodal_patches(), ORIGIN), *_random_contact_sets(seed=2)]:
        for mu in (0.0, 0.3):
            largest = gravity_loads(contacts, mu, com, DIRECTIONS, 20.0)
            some = resists_loads(contacts, mu, com, DIRECTIONS, 1.0, None, torque_scale=0.03)
            np.testing.assert_array_equal(some, largest > 1e-9)
            seen.update(some)
    assert seen == {True, False}


def test_held_margin_is_the_smallest_margin_capped_at_the_target():
    contacts = antipodal_patches()
    cases = [(contacts, np.array([0, 0, offset]), mass)
             for offset, mass in ((0.0, 0.3), (0.05, 0.3), (0.1, 0.3), (0.0, 5.0))]
    cases += [(c, com, 0.3) for c, com in _random_contact_sets(seed=3)]
    held = set()
    for contacts, com, mass in cases:
        for mu in (0.0, 0.5):
            quality = contacts_quality(contacts, ObjectProperties(com, 0.12),
                                       QualityConfig(mass=mass, friction=mu))
            assert quality.held_margin == min(quality.min_margin, 1.0)
            fresh = contacts_quality(contacts, ObjectProperties(com, 0.12),
                                     QualityConfig(mass=mass, friction=mu))
            assert fresh.holds == (quality.min_margin >= 1.0)  # without the wrench space
            assert "_space" not in fresh.__dict__ and "min_margin" not in fresh.__dict__
            assert quality.holds == (quality.min_margin >= 1.0)
            record = quality.to_dict()  # plain Python types, as JSON needs
            assert type(record["force_closure"]) is bool and type(record["epsilon"]) is float
            held.add(quality.held_margin)
    assert 0.0 in held and 1.0 in held and any(0 < h < 1 for h in held)


def test_centre_of_mass_of_a_closed_mesh_is_that_of_its_solid():
    """A pyramid's centre of mass lies a quarter of its height above its base (analytic), and
    trimesh's mass properties give the same bits; a mesh that bounds no solid (open, or wound
    inside out, or one face flipped) falls back to the centroid of its surface, as trimesh's
    ``is_volume`` says."""
    import trimesh

    from isf.quality.grasp_quality import _solid_center_of_mass

    cone = trimesh.creation.cone(radius=0.04, height=0.1, sections=24)  # base at z = 0
    centre = _solid_center_of_mass(cone.vertices, cone.faces)
    np.testing.assert_allclose(centre, [0.0, 0.0, 0.025], atol=1e-12)
    for mesh in (cone, trimesh.creation.icosphere(subdivisions=3, radius=0.05),
                 trimesh.creation.annulus(r_min=0.02, r_max=0.04, height=0.03)):
        mesh.apply_translation([0.01, -0.02, 0.03])
        reference = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
        assert reference.is_volume
        assert np.array_equal(_solid_center_of_mass(mesh.vertices, mesh.faces),
                              reference.center_mass)
    one_flipped = cone.faces.copy()
    one_flipped[0] = one_flipped[0, ::-1]
    for faces in (cone.faces[:-1], cone.faces[:, ::-1], one_flipped):
        assert not trimesh.Trimesh(cone.vertices, faces, process=False).is_volume
        assert _solid_center_of_mass(cone.vertices, faces) is None


def test_contacts_of_many_grasps_at_once_are_those_of_each():
    """The batched contact model keeps the grasps apart: each grasp's contacts are those it
    has alone, a grasp off the object has none, and its quality record is the same."""
    from isf.quality import grasps_contacts, grasps_quality

    gripper = isf.load_gripper("three-finger")
    cylinder = isf.open_object("shape:cylinder")
    result = isf.plan(gripper, cylinder, samples=8, seed=1, diversity=None, rank="fit")
    poses = [g.T_object_gripper for g in result.grasps]
    joints = [g.q for g in result.grasps]
    away = poses[0].copy()
    away[:3, 3] += 1.0  # a metre off the object
    poses, joints = np.array([away, *poses]), np.array([joints[0], *joints])
    together = grasps_contacts(gripper, cylinder, poses, joints)
    assert together[0].count == 0 and together[0].patches == 0
    assert sum(c.count > 0 for c in together) >= 4
    for contacts, T, q in zip(together, poses, joints):
        alone = grasp_contacts(gripper, cylinder, T, q)
        for field in ("points", "normals", "surface", "patch"):
            assert np.array_equal(getattr(contacts, field), getattr(alone, field))
    records = [q.to_dict() for q in grasps_quality(gripper, cylinder, poses, joints)]
    assert records == [isf.quality.grasp_quality(gripper, cylinder, T, q).to_dict()
                       for T, q in zip(poses, joints)]


def test_grasps_with_the_same_contacts_share_one_record():
    """A grasp repeated to rounding (the same pose, or moved by 1e-15 m) shares the first
    one's record, which is its own record computed alone up to rounding; a grasp moved by
    a micrometre keeps its own. Sorting the repeats reads no margin and no epsilon."""
    from isf.quality import grasps_quality, quality_rank_key

    gripper = isf.load_gripper("paper-parallel")
    cylinder = isf.open_object("shape:cylinder")
    result = isf.plan(gripper, cylinder, samples=8, seed=1, diversity=None, rank="fit")
    grasp = next(g for g in result.grasps if g.valid)
    rounded, moved = grasp.T_object_gripper.copy(), grasp.T_object_gripper.copy()
    rounded[:3, 3] += 1e-15
    moved[:3, 3] += 1e-6
    poses = np.array([grasp.T_object_gripper, grasp.T_object_gripper, rounded, moved])
    heavy = QualityConfig(mass=3.0)  # the grasp falls short of its weight: margins compared
    records = grasps_quality(gripper, cylinder, poses, np.array([grasp.q] * 4), heavy)
    assert records[1] is records[0] and records[2] is records[0]
    assert records[3] is not records[0]
    order = sorted(range(3), key=lambda k: (quality_rank_key(records[k], 0.0), k))
    assert order == [0, 1, 2]
    assert "_space" not in records[0].__dict__ and "held_margin" not in records[0].__dict__
    assert 0.0 < records[0].held_margin < 1.0
    alone = isf.quality.grasp_quality(gripper, cylinder, rounded, grasp.q, heavy).to_dict()
    shared = records[2].to_dict()
    assert shared.keys() == alone.keys()
    for name, value in alone.items():
        if isinstance(value, (dict, float)):
            assert shared[name] == pytest.approx(value, rel=1e-9)
        else:
            assert shared[name] == value


def test_margins_below_the_target_are_ordered_as_their_values():
    """The ranking orders held margins below the target by Farkas bounds from feasibility
    tests; the order is the one the computed margins (wrench space or LP) give, for margins
    far apart and for contacts moved by 1e-9 to 1e-4 m (margins apart by about as much)."""
    from isf.quality import MARGIN_TARGET, quality_rank_key

    rng = np.random.default_rng(11)
    qualities, normals_of = [], []
    for k in range(30):  # three to five point contacts on a 3 cm sphere, pushing inwards
        points, normals, properties = sphere_contacts(rng, 3, 6)
        for shift in (0.0, 1e-9, 1e-6, 1e-4) if k % 3 == 0 else (0.0,):
            contacts = Contacts.from_points(points + shift * rng.normal(size=points.shape),
                                            normals)
            qualities.append(contacts_quality(contacts, properties, QualityConfig(mass=1.0)))
            normals_of.append(normals / np.linalg.norm(normals, axis=1, keepdims=True))
    lazy = sorted(range(len(qualities)), key=lambda k: quality_rank_key(qualities[k], 0.0))
    held = [min(q.min_margin, MARGIN_TARGET) for q in qualities]
    pushes = [np.linalg.norm(n.sum(axis=0)) / len(n) > 0.5 for n in normals_of]
    full = sorted(range(len(qualities)), key=lambda k: (pushes[k], -held[k],
                                                        qualities[k].com_offset,
                                                        -qualities[k].epsilon))
    assert lazy == full
    assert sum(0 < h < MARGIN_TARGET for h in held) >= 15
