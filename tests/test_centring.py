"""Centring (:mod:`isf.planning.centring`): valid grasps slid toward the centre of mass.

Ground truth: the free directions of contact normals are known in closed form; a parallel grasp
4 cm off the centre of mass of a box slides there exactly (its pads stay on the faces); on a
tapered block the re-closed jaws meet the faces where the block's width is known in closed form,
at the centre of mass trimesh computes; and MuJoCo (``isf.simulation``, independent of the
planner) finds the off-centre grasp turning out of the pads under a load the centred one holds.
"""

import importlib.util
import json
import math

import numpy as np
import pytest
import trimesh

import isf
from isf.collision.checker import CollisionChecker
from isf.config import FitConfig
from isf.exceptions import ConfigError, InvalidInputError
from isf.fitting.engine import score_fit
from isf.fitting.reclosing import reclose_joints
from isf.planning.centring import CentringConfig, GraspCentring, free_directions
from isf.result import FitStatus

#: flat-parallel's pads: centre at z = 0.08 m of the gripper frame, 20 mm tall, at y = +-q.
PAD_CENTRE = np.array([0.0, 0.0, 0.08])
OFFSET = 0.04  # m, the grasp's distance from the box's centre of mass along its long axis
BOX = (0.12, 0.04, 0.03)  # m, the box's extents: the pads close on its 4 cm faces


def _projector(columns: np.ndarray) -> np.ndarray:
    return columns @ columns.T


def test_opposing_pads_leave_the_plane_of_their_faces_free():
    normals = np.array([[0.0, 1.0, 0.0]] * 5 + [[0.0, -1.0, 0.0]] * 5)
    np.testing.assert_allclose(_projector(free_directions(normals, 0.1)), np.diag([1.0, 0.0, 1.0]),
                               atol=1e-12)


def test_three_fingertips_around_an_axis_leave_only_the_axis_free():
    angles = np.radians([90.0, 210.0, 330.0])
    normals = np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], axis=1)
    np.testing.assert_allclose(_projector(free_directions(normals, 0.1)), np.diag([0.0, 0.0, 1.0]),
                               atol=1e-12)


def test_normals_in_every_direction_leave_nothing_free():
    normals = trimesh.creation.icosphere(subdivisions=2).vertex_normals
    assert free_directions(normals, 0.1).shape == (3, 0)


@pytest.fixture(scope="module")
def off_centre():
    """flat-parallel squeezing the box's faces OFFSET from its centre of mass, fitted (scored)
    where it stands, with the plan's collision check and the object's centre of mass."""
    gripper = isf.load_gripper("flat-parallel")
    mesh = trimesh.creation.box(extents=BOX)
    obj = isf.load_object(mesh)
    T = np.eye(4)
    T[:3, 3] = np.array([OFFSET, 0.0, 0.0]) - PAD_CENTRE
    q = np.array([BOX[1] / 2])
    config = FitConfig()
    result = score_fit(gripper, obj, T, q, config, FitStatus.CONVERGED, (), 0.0)
    checker = CollisionChecker(gripper, obj)
    report = checker.check(T, q)
    assert report.collision_free and result.all_surfaces_in_contact
    centring = GraspCentring(gripper, obj, mesh.center_mass, checker, config)
    return gripper, mesh, obj, result, report, centring


def test_an_off_centre_box_grasp_slides_to_the_centre_of_mass(off_centre):
    gripper, _, obj, result, report, centring = off_centre
    centred = centring.centre(result, report)
    T = centred.result.T_object_gripper
    moved = T[:3, 3] - result.T_object_gripper[:3, 3]
    # along the faces only (the pads' normal is y), by the offset (to the spacing of the pads'
    # sampled points, whose mean is not exactly the pads' centre)
    assert moved[1] == 0.0
    np.testing.assert_allclose(moved, [-OFFSET, 0.0, 0.0], atol=5e-4)
    assert centred.shift == pytest.approx(np.linalg.norm(moved))
    # the pads' points now centre on the centre of mass (the box's centre) in x and z
    points, _ = gripper.contact_points(centred.result.q)
    centre = np.mean([points[gripper.point_surface == k].mean(axis=0) for k in (0, 1)], axis=0)
    np.testing.assert_allclose((T[:3, :3] @ centre + T[:3, 3])[[0, 2]], [0.0, 0.0], atol=1e-9)
    np.testing.assert_array_equal(centred.result.q, result.q)
    # a fresh check and score of the slid state agree with what the centring kept
    assert CollisionChecker(gripper, obj).check(centred.result.T_object_gripper,
                                                centred.result.q).collision_free
    assert centred.result.mean_distance <= result.mean_distance + 1e-6
    assert centred.result.all_surfaces_in_contact


@pytest.mark.parametrize("q_start", [0.025, 0.018])
def test_reclosing_puts_the_pads_on_the_faces_from_open_and_from_pressed(off_centre, q_start):
    """flat-parallel's joint is half the jaw width: on the 4 cm faces it is 2 cm, whether the
    pads start 5 mm off the faces or 2 mm inside them."""
    gripper, _, obj, result, _, _ = off_centre
    q = reclose_joints(gripper, obj, result.T_object_gripper, np.array([q_start]))
    np.testing.assert_allclose(q, [BOX[1] / 2], atol=1e-9)


def test_reclosing_leaves_the_joints_of_pads_off_the_object_alone(off_centre):
    gripper, _, obj, result, _, _ = off_centre
    away = result.T_object_gripper.copy()
    away[:3, 3] += [0.0, 0.0, 0.2]  # the pads 20 cm beyond the box
    np.testing.assert_array_equal(reclose_joints(gripper, obj, away, result.q), result.q)


#: the tapered block: its width (along y) grows linearly from TAPER[0] at x = -6 cm to TAPER[1]
#: at x = +6 cm; 3 cm thick along z.
TAPER = (0.036, 0.044)


def _tapered_block() -> trimesh.Trimesh:
    x, z = 0.06, 0.015
    corners = [(sx * x, sy * w / 2, sz * z) for sx, w in ((-1, TAPER[0]), (1, TAPER[1]))
               for sy in (-1, 1) for sz in (-1, 1)]
    return trimesh.convex.convex_hull(np.array(corners))


def _width(x: float) -> float:
    return TAPER[0] + (TAPER[1] - TAPER[0]) * (x + 0.06) / 0.12


@pytest.mark.parametrize("reclose", [True, False])
def test_a_grasp_on_a_tapered_block_slides_to_the_centre_of_mass_when_its_jaws_reclose(reclose):
    """Started 4 cm off the centre of mass on the wide end, the jaws fitted there: moved to the
    centre of mass with its joints fixed the pads stand off the narrower faces (the mean
    distance grows by more than the slack), so the fixed-joint centring stops short; re-closed,
    the grasp reaches the centre of mass with its jaws at the block's width there."""
    gripper = isf.load_gripper("flat-parallel")
    mesh = _tapered_block()
    com = mesh.center_mass
    obj = isf.load_object(mesh)
    start = com[0] + OFFSET
    T = np.eye(4)
    T[:3, 3] = np.array([start, 0.0, 0.0]) - PAD_CENTRE
    q = reclose_joints(gripper, obj, T, np.array([0.03]))
    np.testing.assert_allclose(q, [_width(start) / 2], atol=2e-5)
    config = FitConfig()
    result = score_fit(gripper, obj, T, q, config, FitStatus.CONVERGED, (), 0.0)
    checker = CollisionChecker(gripper, obj)
    report = checker.check(T, q)
    assert report.collision_free and result.all_surfaces_in_contact
    centring = GraspCentring(gripper, obj, com, checker, config, CentringConfig(reclose=reclose))
    centred = centring.centre(result, report).result
    points, _ = gripper.contact_points(centred.q)
    pads = centred.T_object_gripper[:3, :3] @ points.mean(axis=0) + centred.T_object_gripper[:3, 3]
    if reclose:
        np.testing.assert_allclose(pads[0], com[0], atol=5e-4)
        np.testing.assert_allclose(centred.q, [_width(pads[0]) / 2], atol=2e-5)
        assert centred.all_surfaces_in_contact
        assert checker.check(centred.T_object_gripper, centred.q).collision_free
    else:
        assert pads[0] - com[0] > 0.01
        np.testing.assert_array_equal(centred.q, q)


def test_an_invalid_grasp_is_not_moved(off_centre):
    gripper, _, obj, result, report, centring = off_centre
    T, config = result.T_object_gripper, FitConfig()
    pressed = np.array([BOX[1] / 4])  # the pads 1 cm inside the faces
    colliding = CollisionChecker(gripper, obj).check(T, pressed)
    assert not colliding.collision_free
    pressing = score_fit(gripper, obj, T, pressed, config, FitStatus.CONVERGED, (), 0.0)
    assert centring.centre(pressing, colliding).shift == 0.0
    opened = np.array([BOX[1]])  # the pads 2 cm off the faces
    apart = score_fit(gripper, obj, T, opened, config, FitStatus.CONVERGED, (), 0.0)
    assert not apart.all_surfaces_in_contact
    assert centring.centre(apart, report).shift == 0.0


@pytest.mark.skipif(importlib.util.find_spec("mujoco") is None
                    or importlib.util.find_spec("coacd") is None,
                    reason="the physics test needs isf[sim] (mujoco, coacd)")
def test_the_centred_grasp_holds_where_the_fitted_one_turns_out_of_the_pads(off_centre):
    """Load the box above what the pads' friction torque resists at 4 cm (the bound of
    tests/test_validate.py: 2 mu N a sqrt 2 / (g d), 2 x 2 cm pads) and below what they resist as
    a pure force (2 mu N / g): the off-centre grasp turns, the centred one holds."""
    from dataclasses import replace

    from isf.simulation import Outcome, SimulationSettings, object_body, validate_grasp

    gripper, mesh, _, result, report, centring = off_centre
    settings = SimulationSettings(friction=0.5)
    mu, N, g, a = settings.friction, settings.finger_force, 9.81, 0.01
    mass = 1.5 * 2 * mu * N * a * math.sqrt(2) / (g * OFFSET)
    assert mass < 0.6 * 2 * mu * N / g
    settings = replace(settings, mass=mass)
    body = object_body(mesh.vertices, mesh.faces, mass)
    before = validate_grasp(gripper, body, result.T_object_gripper, result.q, settings)
    centred = centring.centre(result, report).result
    after = validate_grasp(gripper, body, centred.T_object_gripper, centred.q, settings)
    assert before.outcome is Outcome.SLIPPED, before
    assert after.outcome is Outcome.HELD, after


def test_plans_centre_by_default_and_record_it(tmp_path):
    from isf.planning.plan_json import SCHEMA_PATH, write_plan_json

    jsonschema = pytest.importorskip("jsonschema")
    obj = isf.open_object("shape:capsule")
    centred = isf.plan("paper-parallel", obj, samples=12, sampler="uniform", seed=2)
    plain = {g.sample_index: g for g in isf.plan("paper-parallel", obj, samples=12,
                                                   sampler="uniform", seed=2,
                                                   centring=False).grasps}
    assert centred.centring == CentringConfig()
    moved = [g for g in centred.grasps if g.centred]
    assert moved, "no grasp was centred: choose another seed"
    com = obj.centroid  # the capsule is symmetric: its centre of mass is its centroid
    for grasp in centred.grasps:
        fit = plain[grasp.sample_index]
        if grasp.centred:
            assert grasp.valid and fit.valid
            closer = (np.linalg.norm(grasp.fit.contact_points.mean(axis=0) - com)
                      < np.linalg.norm(fit.fit.contact_points.mean(axis=0) - com))
            assert closer
            if not np.array_equal(grasp.q, fit.q):  # re-closed: its pads on the object again
                assert grasp.fit.all_surfaces_in_contact
            # the history is the fit's: it ends where the fit ended, not at the slid grasp
            np.testing.assert_array_equal(grasp.fit.history[-1].T_object_gripper,
                                          fit.T_object_gripper)
        elif fit.valid:  # a valid grasp the centring could not move keeps its fit
            np.testing.assert_array_equal(grasp.T_object_gripper, fit.T_object_gripper)
    path = write_plan_json(centred, tmp_path / "plan.json")
    data = json.loads(path.read_text())
    jsonschema.validate(data, json.loads(SCHEMA_PATH.read_text()))
    assert [g["centred"] for g in data["grasps"]] == [g.centred for g in centred.grasps]
    assert data["centring"]["fractions"] == list(CentringConfig().fractions)


def test_bad_centring_arguments_are_refused_in_one_line():
    with pytest.raises(InvalidInputError, match="centring must be True, False or"):
        isf.plan("paper-parallel", "shape:cylinder", samples=1, centring="yes")
    with pytest.raises(ConfigError, match="fractions"):
        CentringConfig(fractions=())
    with pytest.raises(ConfigError, match="fractions"):
        CentringConfig(fractions=(1.0, 1.5))
    with pytest.raises(ConfigError, match="reclose"):
        CentringConfig(reclose="yes")


def test_cli_no_centring_writes_no_centring(tmp_path):
    from isf.cli import main

    out = tmp_path / "plan.json"
    assert main(["plan", "-g", "paper-parallel", "-o", "shape:capsule", "-n", "6",
                 "--no-centring", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["centring"] is None and not any(g["centred"] for g in data["grasps"])


def test_the_pose_scorer_gives_score_fits_figures(off_centre):
    """:class:`isf.fitting.engine.PoseScorer` (what the centring tries moves with) against
    :func:`isf.fitting.engine.score_fit` (the FitResult of a state), at poses around the
    grasp, some touching, some not."""
    from isf.fitting.engine import PoseScorer

    gripper, _, obj, result, _, _ = off_centre
    config = FitConfig()
    scorer = PoseScorer(gripper, obj, config, result.q)
    rng = np.random.default_rng(5)
    for _ in range(12):
        T = result.T_object_gripper.copy()
        T[:3, 3] += rng.normal(scale=0.01, size=3)
        expected = score_fit(gripper, obj, T, result.q, config, FitStatus.CONVERGED, (), 0.0)
        got = scorer(T)
        assert got.mean_distance == expected.mean_distance
        np.testing.assert_array_equal(
            got.surface_contact, [expected.surface_contact[s.name] for s in gripper.surfaces])
