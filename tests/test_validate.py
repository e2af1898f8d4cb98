"""The physics test of grasps (isf.simulation, ``isf validate``) against known cases.

Ground truth is analytic: a box squeezed between parallel pads at its centre holds; a tapered
prism whose faces lean out of the friction cone (tan(alpha) > mu) is squeezed out, one that
leans inside it holds; a grasp that sinks the pads into the object is flagged; and a box on a
plane tilted below / above atan(mu) stays / slides, which shows the friction MuJoCo applies is
the coefficient set.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import math

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
from isf.simulation.world import physics_spec

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


def _tapered_prism(alpha: float, half_width: float, height: float = 0.03, length: float = 0.03):
    """A prism along x whose half-width in y is ``half_width + z tan(alpha)`` (z from -h/2 to h/2):
    widest towards the fingertips, where no finger geometry lies beyond the pads."""
    import trimesh

    section = [(-height / 2, half_width - height / 2 * math.tan(alpha)),
               (height / 2, half_width + height / 2 * math.tan(alpha))]
    corners = [(x, s * w, z) for x in (-length / 2, length / 2) for z, w in section for s in (-1, 1)]
    mesh = trimesh.convex.convex_hull(np.array(corners))
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
    assert data["validation_settings"]["friction"] == 0.5
    assert "grasps held in all six directions" in capsys.readouterr().out
    assert code == (0 if any(g["validation"]["outcome"] == "held" for g in data["grasps"][:2]) else 1)


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
    for bad, message in (('joint="left_finger_joint" sign="2"', "sign attribute of 1 or -1"),
                         ('joint="right_finger_joint" sign="1"', "names no actuated joint")):
        path = tmp_path / "bad.urdf"
        path.write_text(text.replace('<isf:closing joint="left_finger_joint" sign="-1"/>',
                                     f"<isf:closing {bad}/>"))
        with pytest.raises(GripperDescriptionError, match=message):
            isf.load_gripper(path)


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
