"""Registration never picks a face that cannot touch: fingers made of several collision elements.

The gripper is written here: two prismatic fingers, each a body box (8 x 10 x 65 mm) with a pad
box (3 x 10 x 20 mm) in front of the body's inner face at its distal end, a separate
``<collision>``. The body's inner face lies under the pad (where the pad sits) and 3 mm behind
the pad's face (elsewhere); the only face that can touch an object between the fingers is the
pad's. The geometry is boxes, so the answers are known by construction.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import isf
from isf.registration import ContactSpec, suggest_contacts, tag_urdf
from isf.registration.occlusion import blocked, contact_warnings
from isf.registration.preview import preview_tagged

BODY = (0.008, 0.010, 0.065)  # x (towards the other finger), y, z (along the approach)
PAD = (0.003, 0.010, 0.020)
OPEN = 0.03  # each finger's body centre sits this far from the middle, metres


def _finger(side: str, sign: float, pad_name: str | None, pad_length: float) -> str:
    """A finger link: the body box and, in front of its inner face at the tip, the pad box."""
    body_x = 0.0
    pad_x = -sign * (BODY[0] / 2 + PAD[0] / 2)  # on the inner side (towards the middle)
    pad_z = BODY[2] / 2 - pad_length / 2  # at the distal end
    name = f' name="{pad_name}"' if pad_name else ""
    return f"""
  <link name="{side}_finger">
    <collision name="{side}_body"><origin xyz="{body_x} 0 0"/>
      <geometry><box size="{BODY[0]} {BODY[1]} {BODY[2]}"/></geometry></collision>
    <collision{name}><origin xyz="{pad_x} 0 {pad_z}"/>
      <geometry><box size="{PAD[0]} {PAD[1]} {pad_length}"/></geometry></collision>
  </link>
  <joint name="{side}_joint" type="prismatic">
    <parent link="palm"/><child link="{side}_finger"/>
    <origin xyz="{sign * OPEN} 0 {0.02 + BODY[2] / 2}"/><axis xyz="{-sign} 0 0"/>
    <limit lower="0" upper="0.025" effort="10" velocity="1"/>
  </joint>"""


def _urdf(tmp_path, pad_name: str | None = "pad", pad_length: float = PAD[2]) -> str:
    """The gripper's URDF; pads named ``left_<pad_name>`` (unnamed for None)."""
    left = _finger("left", 1.0, pad_name and f"left_{pad_name}", pad_length)
    right = _finger("right", -1.0, pad_name and f"right_{pad_name}", pad_length)
    text = f"""<?xml version="1.0"?>
<robot name="padded">
  <link name="palm">
    <collision><geometry><box size="0.09 0.03 0.02"/></geometry></collision>
  </link>{left}{right}
</robot>
"""
    path = tmp_path / "padded.urdf"
    path.write_text(text)
    return path


def _pad_face_x(sign: float) -> float:
    """x of the pad's inner face in the finger's link frame."""
    return -sign * (BODY[0] / 2 + PAD[0])


@pytest.mark.parametrize(("pad_name", "pad_length"),
                         [("pad", PAD[2]), (None, PAD[2]), ("pad", BODY[2])])
def test_the_suggestion_picks_the_pad_not_the_body_face_behind_it(tmp_path, pad_name,
                                                                   pad_length):
    """Each suggested contact reads the pad element only, faces the other finger, and what it
    selects lies on the pad's inner face (x known from the boxes), not on the body's (3 mm
    further back; under the pad where the pad covers it)."""
    src = _urdf(tmp_path, pad_name, pad_length)
    specs = suggest_contacts(src, points=64)
    assert len(specs) == 2
    for spec in specs:
        sign = 1.0 if spec.link == "left_finger" else -1.0
        expected = f"{spec.link.split('_')[0]}_pad" if pad_name else f"{spec.link}_1"
        assert spec.geometry == expected
        assert np.allclose(spec.normal, (-sign, 0.0, 0.0), atol=1e-3)
    preview = tag_urdf(src, tmp_path / "tagged.urdf", specs)
    assert preview.ok, preview.problems
    for surface in preview.surfaces:
        sign = 1.0 if surface.link == "left_finger" else -1.0
        xs = surface.triangles[..., 0]
        assert np.allclose(xs, _pad_face_x(sign), atol=1e-9)
        assert surface.area == pytest.approx(PAD[1] * pad_length, rel=1e-9)
    gripper = isf.load_gripper(tmp_path / "tagged.urdf")
    assert contact_warnings(gripper) == []


@pytest.mark.parametrize("pad_length", [PAD[2], BODY[2]])
def test_the_check_flags_a_surface_tagged_on_the_buried_face(tmp_path, pad_length):
    """A contact tagged on the body element (its inner face: under the pad and 3 mm behind its
    face; with a pad as long as the body, wholly under it) is reported as unable to touch."""
    src = _urdf(tmp_path, pad_length=pad_length)
    specs = [ContactSpec(f"{side}_face", f"{side}_finger", geometry=f"{side}_body",
                         normal=(-sign, 0, 0), max_angle=0.3, points=64)
             for side, sign in (("left", 1.0), ("right", -1.0))]
    tag_urdf(src, tmp_path / "buried.urdf", specs)
    warnings = contact_warnings(isf.load_gripper(tmp_path / "buried.urdf"))
    assert len(warnings) == 2 and all("cannot touch" in w for w in warnings)
    assert {w.split("'")[1] for w in warnings} == {"left_face", "right_face"}


def test_the_check_flags_a_surface_facing_away(tmp_path):
    """A contact on the body's outer face (normal away from the other finger) is reported as
    facing away from every other contact surface."""
    src = _urdf(tmp_path)
    specs = [ContactSpec("left_out", "left_finger", geometry="left_body", normal=(1, 0, 0),
                         max_angle=0.3, points=64),
             ContactSpec("right_pad", "right_finger", geometry="right_pad", normal=(1, 0, 0),
                         max_angle=0.3, points=64)]
    tag_urdf(src, tmp_path / "away.urdf", specs)
    warnings = contact_warnings(isf.load_gripper(tmp_path / "away.urdf"))
    assert len(warnings) == 1 and "'left_out'" in warnings[0] and "faces away" in warnings[0]


@pytest.mark.parametrize("name", ["paper-parallel", "flat-parallel", "three-finger"])
def test_bundled_grippers_raise_no_warning(name):
    assert contact_warnings(isf.load_gripper(name)) == []


def test_blocked_against_an_analytic_box():
    """A 10 mm cube centred at the origin: points on the plane z = -5 mm facing down are free,
    facing up they are covered (inside the closed box), and points 3 mm below it facing up have
    it 3 mm in front (blocked at depth 5 mm, free at depth 2 mm)."""
    box = trimesh.creation.box((0.01, 0.01, 0.01))
    rng = np.random.default_rng(0)
    xy = rng.uniform(-0.004, 0.004, (50, 2))
    on = np.column_stack([xy, np.full(50, -0.005)])
    up, down = np.tile([0.0, 0.0, 1.0], (50, 1)), np.tile([0.0, 0.0, -1.0], (50, 1))
    assert not blocked(on, down, [box]).any()
    assert blocked(on, up, [box]).all()
    below = on - [0.0, 0.0, 0.003]
    assert blocked(below, up, [box], depth=0.005).all()
    assert not blocked(below, up, [box], depth=0.002).any()
    outside = np.column_stack([xy + 0.02, np.full(50, -0.008)])  # beside the box: rays miss
    assert not blocked(outside, up, [box], depth=0.05).any()


def test_inspect_export_previews_any_tagged_file(tmp_path):
    """``preview_tagged`` (``isf inspect --export``) selects what ``tag_urdf`` selected."""
    src = _urdf(tmp_path)
    written = tag_urdf(src, tmp_path / "tagged.urdf", suggest_contacts(src, points=64))
    read = preview_tagged(tmp_path / "tagged.urdf")
    assert [s.name for s in read.surfaces] == [s.name for s in written.surfaces]
    for a, b in zip(read.surfaces, written.surfaces):
        assert np.array_equal(a.triangles, b.triangles)
    out = read.export(tmp_path / "preview.ply")
    mesh = trimesh.load(out, force="mesh")
    red = np.all(mesh.visual.face_colors[:, :3] == (220, 30, 30), axis=1)
    assert red.sum() == sum(len(s.triangles) for s in written.surfaces)


def test_isf_inspect_warns_and_exports(tmp_path, capsys):
    """``isf inspect`` prints a warning per buried surface (exit 0: the file is valid) and
    ``--export`` writes the preview."""
    from isf.cli import main

    src = _urdf(tmp_path)
    specs = [ContactSpec(f"{side}_face", f"{side}_finger", geometry=f"{side}_body",
                         normal=(-sign, 0, 0), max_angle=0.3, points=64)
             for side, sign in (("left", 1.0), ("right", -1.0))]
    tag_urdf(src, tmp_path / "buried.urdf", specs)
    capsys.readouterr()
    assert main(["inspect", str(tmp_path / "buried.urdf"), "--export",
                 str(tmp_path / "buried.glb")]) == 0
    out = capsys.readouterr().out
    assert out.count("warning: contact ") == 2 and (tmp_path / "buried.glb").is_file()
    assert main(["inspect", "paper-parallel"]) == 0
    assert "warning:" not in capsys.readouterr().out
