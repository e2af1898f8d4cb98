"""isf's error hierarchy: one module, every error an ISFError, picklable with its data, and the
data of real failures matching what an independent reading of the failing input gives."""

from __future__ import annotations

import inspect
import pickle
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import trimesh

import isf
from isf import assets, exceptions, registration
from isf.exceptions import (
    AssetFetchError,
    GeometryLoadError,
    GripperDescriptionError,
    ISFError,
    JointLimitError,
    JointLimitViolation,
    MeshNotFoundError,
    ModelBuildError,
    ObjectLoadError,
    QPStepError,
    RegistrationError,
    SurfaceSelectionError,
    UnknownAssetError,
    URDFReadError,
    YCBNotFoundError,
)
from isf.gripper.mesh_paths import mesh_path_candidates
from isf.gripper.surface_sampling import load_geometry, select_faces
from isf.gripper.urdf_model import build_model
from isf.gripper.urdf_tags import ContactTag, parse_tagged_urdf

ERRORS = [
    obj
    for name in exceptions.__all__
    if inspect.isclass(obj := getattr(exceptions, name)) and issubclass(obj, Exception)
    and not issubclass(obj, Warning)
]

ONE_LINK = """<robot name="one" xmlns:isf="urn:isf:gripper:1">
  <link name="palm"><collision><geometry>{geometry}</geometry></collision></link>
  <link name="finger"><collision><geometry><box size="0.01 0.01 0.01"/></geometry></collision>
  </link>
  <joint name="slide" type="prismatic"><parent link="palm"/><child link="finger"/>
    <axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
  <isf:contact name="pad" link="finger" normal="0 -1 0"/>
</robot>
"""


def _round_trip(error: BaseException) -> BaseException:
    """Pickle and unpickle ``error``; check type, message and every attribute survive."""
    copy = pickle.loads(pickle.dumps(error))
    assert type(copy) is type(error)
    assert str(copy) == str(error) and copy.args == error.args
    assert copy.__dict__.keys() == error.__dict__.keys()
    for key, value in error.__dict__.items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(copy.__dict__[key], value)
        elif key != "problem":
            assert copy.__dict__[key] == value, key
    return copy


def _write(tmp_path: Path, text: str, name: str = "g.urdf") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# ----------------------------------------------------------------------------- the hierarchy
def test_every_error_is_an_isf_error_and_exported_from_one_module():
    assert {e.__name__ for e in ERRORS} >= {
        "RegistrationError", "AssetFetchError", "YCBNotFoundError", "UnknownAssetError",
        "MeshNotFoundError", "URDFReadError", "ModelBuildError", "GeometryLoadError",
        "SurfaceSelectionError", "JointLimitError", "QPStepError",
    }
    for error in ERRORS:
        assert issubclass(error, ISFError), error
        assert error.__module__ == "isf.exceptions", error
    assert issubclass(exceptions.ISFWarning, UserWarning)
    assert issubclass(JointLimitError, isf.InvalidInputError)
    assert issubclass(YCBNotFoundError, AssetFetchError)


def test_old_import_locations_name_the_same_classes():
    from isf.gripper import mesh_paths, surface_sampling, urdf_model, urdf_tags

    assert assets.AssetFetchError is AssetFetchError
    assert assets.YCBNotFoundError is YCBNotFoundError
    assert assets.UnknownAssetError is UnknownAssetError
    assert mesh_paths.MeshNotFoundError is MeshNotFoundError
    assert urdf_tags.URDFReadError is URDFReadError
    assert urdf_model.ModelBuildError is ModelBuildError
    assert surface_sampling.GeometryLoadError is GeometryLoadError
    assert surface_sampling.SurfaceSelectionError is SurfaceSelectionError
    assert registration.RegistrationError is RegistrationError


# ----------------------------------------------------------------------------- gripper files
def test_missing_mesh(tmp_path):
    path = _write(tmp_path, ONE_LINK.format(geometry='<mesh filename="package://kit/gone.stl"/>'))
    doc = parse_tagged_urdf(path.read_text())
    geom = doc.links["palm"].collisions[0]
    with pytest.raises(MeshNotFoundError) as info:
        load_geometry(geom, tmp_path, {"kit": tmp_path / "kit"})
    error = _round_trip(info.value)
    assert error.filename == "package://kit/gone.stl"
    assert error.link == "palm"
    assert error.tried == mesh_path_candidates(
        "package://kit/gone.stl", tmp_path, {"kit": tmp_path / "kit"}
    )
    assert error.tried[0] == tmp_path / "kit" / "gone.stl"
    assert "\n" not in str(error) and "package_dirs=" in str(error)

    # loading the whole gripper collects the same message among its problems
    with pytest.raises(GripperDescriptionError) as info:
        isf.load_gripper(path)
    error = _round_trip(info.value)
    assert error.source == str(path)
    assert any("mesh 'package://kit/gone.stl' not found" in e for e in error.errors)


@pytest.mark.parametrize("text", [
    "<robot name='r'><link name='a'></robot>",
    "<robot name='r'>\n  <link name='a'/>\n  <joint name='j' type='fixed'>\n</robot>",
    # an undeclared prefix (declared by the reader) before the error on the same line
    "<robot name='r'><drake:x a='1'/><link name='a'></robot>",
])
def test_malformed_urdf(text):
    # the position a plain parse reports (a prefix-free name of the same length)
    with pytest.raises(ET.ParseError) as expected:
        ET.fromstring(text.replace("drake:", "drakeQ"))
    with pytest.raises(URDFReadError) as info:
        parse_tagged_urdf(text)
    error = _round_trip(info.value)
    assert (error.line, error.column) == expected.value.position
    assert error.root_tag is None
    assert str(error) == (
        f"not valid XML (mismatched tag: line {error.line}, column {error.column}): "
        "fix the file's syntax"
    )


def test_urdf_with_another_root():
    with pytest.raises(URDFReadError, match="expected <robot>") as info:
        parse_tagged_urdf("<sdf version='1.6'><model name='m'/></sdf>")
    error = _round_trip(info.value)
    assert error.root_tag == "sdf" and error.line is None and error.column is None


def test_model_that_pinocchio_rejects(tmp_path):
    # a joint whose parent link does not exist
    text = ONE_LINK.format(geometry='<box size="0.1 0.1 0.1"/>').replace(
        '<parent link="palm"/>', '<parent link="nowhere"/>'
    )
    with pytest.raises((RuntimeError, ValueError)) as expected:
        pin.buildModelFromXML(text, mimic=True)
    with pytest.raises(ModelBuildError) as info:
        build_model(text, parse_tagged_urdf(text))
    error = _round_trip(info.value)
    assert error.reason == str(expected.value)
    assert error.fix == "fix the URDF structure"
    assert str(error) == f"Pinocchio cannot build the kinematic model ({error.reason}): {error.fix}"


def test_unreadable_mesh_and_unsupported_shape(tmp_path):
    (tmp_path / "broken.stl").write_text("solid nothing\nthis is not an STL\n")
    path = _write(tmp_path, ONE_LINK.format(geometry='<mesh filename="broken.stl"/>'))
    geom = parse_tagged_urdf(path.read_text()).links["palm"].collisions[0]
    with pytest.raises(GeometryLoadError) as info:
        load_geometry(geom, tmp_path)
    error = _round_trip(info.value)
    assert error.path == tmp_path / "broken.stl" and error.shape == "mesh"

    text = ONE_LINK.format(geometry='<capsule radius="0.01" length="0.05"/>')
    geom = parse_tagged_urdf(text).links["palm"].collisions[0]
    with pytest.raises(GeometryLoadError, match="unsupported geometry <capsule>") as info:
        load_geometry(geom, tmp_path)
    error = _round_trip(info.value)
    assert error.path is None and error.shape == "capsule"


def test_selection_that_keeps_no_face():
    box = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    tag = ContactTag("pad", "finger", normal=np.array([0.0, -1.0, 0.0]), max_angle=0.3,
                     box_min=np.array([0.5, 0.5, 0.5]))  # a box far from the link's geometry
    assert not np.any(np.all(box.triangles.mean(axis=1) >= 0.5, axis=1))
    with pytest.raises(SurfaceSelectionError, match="keeps no face") as info:
        select_faces(tag, [box])
    error = _round_trip(info.value)
    assert (error.contact, error.link) == ("pad", "finger")


# ----------------------------------------------------------------------------- registration
def test_registration_errors_name_the_file(tmp_path):
    missing = tmp_path / "absent.urdf"
    with pytest.raises(RegistrationError, match="is not a file") as info:
        registration.tag_urdf(missing, tmp_path / "out.urdf",
                                  [registration.ContactSpec("pad", "finger")])
    assert _round_trip(info.value).source == missing

    # a gripper with one finger: the suggestion needs two fingertips
    path = _write(tmp_path, ONE_LINK.format(geometry='<box size="0.1 0.1 0.1"/>'))
    with pytest.raises(RegistrationError, match="at least two") as info:
        registration.suggest_contacts(path)
    assert _round_trip(info.value).source == path.resolve()

    with pytest.raises(RegistrationError, match="non-empty") as info:
        registration.ContactSpec("", "finger")
    assert _round_trip(info.value).source is None


# ----------------------------------------------------------------------------- assets
def test_unknown_asset_names():
    with pytest.raises(UnknownAssetError) as info:
        assets.vendor_gripper("no-such-hand")
    error = _round_trip(info.value)
    assert error.name == "no-such-hand"
    assert error.known == assets.vendor_grippers(include_arms=True)
    assert isinstance(error, LookupError)

    with pytest.raises(UnknownAssetError) as info:
        assets.benchmark_objects("no-such-group")
    error = _round_trip(info.value)
    assert error.name == "no-such-group" and "stanford" in error.known

    with pytest.raises(UnknownAssetError) as info:
        assets.prefetch(["no-such-package", "pybullet"])
    error = _round_trip(info.value)
    assert error.name == ["no-such-package"] and "pybullet" in error.known


def test_missing_ycb_folder(tmp_path, monkeypatch):
    folder = tmp_path / "not-there"
    monkeypatch.setenv("ISF_YCB_DIR", str(folder))
    with pytest.raises(YCBNotFoundError, match="ISF_YCB_DIR") as info:
        assets.benchmark_object("ycb:banana")
    assert _round_trip(info.value).searched == [folder]

    monkeypatch.delenv("ISF_YCB_DIR")
    monkeypatch.chdir(tmp_path)
    if any((f / "shared" / "data" / "ycb").is_dir() for f in (tmp_path, *tmp_path.parents)):
        pytest.skip("a shared/data/ycb folder lies above the temporary folder")
    with pytest.raises(YCBNotFoundError, match="no YCB folder") as info:
        assets.benchmark_objects("ycb")
    searched = _round_trip(info.value).searched
    assert searched[0] == tmp_path / "shared" / "data" / "ycb"
    assert len(searched) == len(tmp_path.parents) + 1


def test_object_urdf_without_a_visual_mesh(tmp_path):
    urdf = _write(tmp_path, "<robot name='o'><link name='l'/></robot>")
    with pytest.raises(AssetFetchError, match="no visual mesh") as info:
        assets._urdf_visual_mesh(urdf)
    error = _round_trip(info.value)
    assert error.path == urdf and error.package is None


# ----------------------------------------------------------------------------- objects
def test_object_load_errors_name_the_source(tmp_path):
    missing = tmp_path / "absent.stl"
    with pytest.raises(ObjectLoadError, match="does not exist") as info:
        isf.load_object(missing)
    assert _round_trip(info.value).source == missing

    empty = tmp_path / "points.xyz"
    empty.write_text("# a comment and no points\n")
    with pytest.raises(ObjectLoadError, match="holds no points") as info:
        isf.load_object(str(empty))
    assert _round_trip(info.value).source == empty

    with pytest.raises(ObjectLoadError, match="shape") as info:
        isf.open_object("shape:no-such-shape")
    assert _round_trip(info.value).source == "shape:no-such-shape"

    with pytest.raises(ObjectLoadError, match="shape") as info:
        isf.load_object(np.zeros((5, 4)))
    assert _round_trip(info.value).source is None


# ----------------------------------------------------------------------------- fitting
def test_joints_outside_their_limits(paper_gripper):
    g = paper_gripper
    q = g.upper + 0.5
    with pytest.raises(JointLimitError) as info:
        isf.fit(g, isf.open_object("shape:cylinder"), np.eye(4), q=q)
    error = _round_trip(info.value)
    assert isinstance(error, isf.InvalidInputError)
    assert len(error.violations) == g.n_joints
    for v, name, value, lo, hi in zip(error.violations, g.joint_names, q, g.lower, g.upper):
        assert v == (name, value, lo, hi)
    assert (error.joint, error.value, error.lower, error.upper) == error.violations[0]
    assert "outside their limits" in str(error) and "\n" not in str(error)


def test_joint_limit_error_lists_every_violation():
    error = JointLimitError(
        [JointLimitViolation("a", 0.1, 0.0, 0.04), JointLimitViolation("b", -1.0, 0.0, 1.5)]
    )
    assert str(error) == "joints outside their limits: a=0.1 not in [0, 0.04], b=-1 not in [0, 1.5]"
    assert _round_trip(error).violations == error.violations
    with pytest.raises(ValueError):
        JointLimitError([])


def test_qp_step_error_keeps_problem_and_status():
    problem = {"P": np.eye(2), "q": np.ones(2), "lb": -np.ones(2), "ub": np.ones(2)}
    error = _round_trip(QPStepError(problem, "primal infeasible"))
    assert error.status == "primal infeasible"
    for key, value in problem.items():
        np.testing.assert_array_equal(error.problem[key], value)


def test_unknown_sampler_names_itself_and_the_installed_ones():
    with pytest.raises(isf.SamplerNotFound) as caught:
        isf.get_sampler("no-such-sampler")
    assert caught.value.name == "no-such-sampler"
    assert set(caught.value.known) == set(isf.available_samplers())
    assert {"regret", "uniform"} <= set(caught.value.known)


def test_every_error_class_is_exported_at_the_top_level():
    for name in dir(exceptions):
        value = getattr(exceptions, name)
        if isinstance(value, type) and issubclass(value, (isf.ISFError, isf.ISFWarning)):
            assert getattr(isf, name) is value, f"isf.{name} is not isf.exceptions.{name}"


def test_output_file_error_keeps_its_path_across_processes(tmp_path):
    from isf.exceptions import OutputFileError
    from isf.output_files import check_output_path

    with pytest.raises(OutputFileError) as caught:
        check_output_path(tmp_path)
    copy = _round_trip(caught.value)
    assert copy.path == tmp_path and "is a folder" in str(copy)
