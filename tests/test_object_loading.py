"""Tests of isf.object.loading: every reader, normals against analytic shapes, every error."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from isf.exceptions import InvalidInputError, ObjectLoadError
from isf.object.loading import load_object

RNG_SEED = 7
CENTRE = np.array([0.1, -0.2, 0.3])


# --------------------------------------------------------------------------- helpers


def _ycb_dir() -> Path:
    env = os.environ.get("ISF_YCB_DIR")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "data" / "ycb"


def _sphere_cloud(n: int, radius: float = 0.05, seed: int = RNG_SEED) -> np.ndarray:
    """Random points on a sphere of ``radius`` about CENTRE, shape (n, 3)."""
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return CENTRE + radius * d / np.linalg.norm(d, axis=1, keepdims=True)


def _cylinder_cloud(n: int, radius=0.04, height=0.12, caps=True, seed=RNG_SEED) -> np.ndarray:
    """Uniform random points on a cylinder about the z axis (lateral surface and caps)."""
    rng = np.random.default_rng(seed)
    lateral, cap = 2 * np.pi * radius * height, np.pi * radius**2
    n_lat = int(n * lateral / (lateral + (2 * cap if caps else 0)))
    theta, z = rng.uniform(0, 2 * np.pi, n_lat), rng.uniform(-height / 2, height / 2, n_lat)
    parts = [np.c_[radius * np.cos(theta), radius * np.sin(theta), z]]
    if caps:
        m = (n - n_lat) // 2
        for side in (-1.0, 1.0):
            r, t = radius * np.sqrt(rng.random(m)), rng.uniform(0, 2 * np.pi, m)
            parts.append(np.c_[r * np.cos(t), r * np.sin(t), np.full(m, side * height / 2)])
    return np.vstack(parts)


def _radial(points: np.ndarray) -> np.ndarray:
    """Unit radial directions about the z axis, shape (N, 3)."""
    r = points.copy()
    r[:, 2] = 0.0
    return r / np.linalg.norm(r, axis=1, keepdims=True)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unsigned angle between the lines of unit vectors a and b (degrees)."""
    return np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", a, b)), 0.0, 1.0)))


def _outward_fraction(surface, centre) -> float:
    return float(np.mean(np.einsum("ij,ij->i", surface.points - centre, surface.normals) > 0))


def _write_pcd(path: Path, points: np.ndarray, normals: np.ndarray | None, binary: bool) -> None:
    """A minimal PCL .pcd writer (float32 fields)."""
    fields = ["x", "y", "z"] + (["normal_x", "normal_y", "normal_z"] if normals is not None else [])
    table = points if normals is None else np.hstack([points, normals])
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
        f"FIELDS {' '.join(fields)}\nSIZE {' '.join(['4'] * len(fields))}\n"
        f"TYPE {' '.join(['F'] * len(fields))}\nCOUNT {' '.join(['1'] * len(fields))}\n"
        f"WIDTH {len(table)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(table)}\n"
        f"DATA {'binary' if binary else 'ascii'}\n"
    )
    if binary:
        path.write_bytes(header.encode() + table.astype("<f4").tobytes())
    else:
        path.write_text(
            header + "\n".join(" ".join(f"{v:.8g}" for v in row) for row in table) + "\n"
        )


def _write_ply_cloud(path: Path, points: np.ndarray, normals: np.ndarray) -> None:
    """An ascii PLY with vertices (and normals) but no faces."""
    header = (
        f"ply\nformat ascii 1.0\nelement vertex {len(points)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\nend_header\n"
    )
    rows = "\n".join(" ".join(f"{v:.8g}" for v in row) for row in np.hstack([points, normals]))
    path.write_text(header + rows + "\n")


def _write_seamed_obj(path: Path, mesh: trimesh.Trimesh, invert: bool) -> None:
    """Write a textured-looking OBJ: three fresh v/vt/vn per triangle (seams everywhere)."""
    lines = ["mtllib none.mtl", "o seamed", "usemtl material_0"]
    faces = mesh.faces[:, ::-1] if invert else mesh.faces
    for k, tri in enumerate(faces):
        for v in mesh.vertices[tri]:
            lines.append(f"v {v[0]:.9f} {v[1]:.9f} {v[2]:.9f}")
        lines += [f"vt {0.1 * (k % 7):.3f} {0.2 * j:.3f}" for j in range(3)]
        lines += [f"vn {n:.6f} {n:.6f} {n:.6f}" for n in (0.577,) * 3]
        a = 3 * k + 1
        lines.append(f"f {a}/{a}/{a} {a + 1}/{a + 1}/{a + 1} {a + 2}/{a + 2}/{a + 2}")
    path.write_text("\n".join(lines) + "\n")


# --------------------------------------------------------------------------- meshes


def test_sphere_mesh_normals_are_radial_and_outward():
    mesh = trimesh.creation.icosphere(subdivisions=6, radius=0.05)
    mesh.apply_translation(CENTRE)
    surface = load_object(mesh)
    d = surface.points - CENTRE
    r = np.linalg.norm(d, axis=1)
    err = np.linalg.norm(surface.normals - d / r[:, None], axis=1)
    assert surface.is_mesh and 2000 <= surface.n_points <= 4000
    assert np.allclose(r, 0.05, atol=2e-4)  # on the facets of the sphere
    assert err.max() < 1.5e-2 and err.mean() < 1e-2  # facets deviate from the sphere by ~1e-2
    assert np.allclose(np.linalg.norm(surface.normals, axis=1), 1.0)
    assert np.allclose(surface.centroid, CENTRE, atol=1e-3)
    assert np.allclose(surface.centroid, surface.points.mean(axis=0))
    # Evenly spaced: nearest-neighbour gaps are of the order of the voxel size.
    gaps = cKDTree(surface.points).query(surface.points, k=2)[0][:, 1]
    assert 0.3 < np.median(gaps) / surface.spacing < 1.2
    assert len(surface.mesh_faces) == len(mesh.faces)


@pytest.mark.parametrize("flip_fraction", [1.0, 0.3])
def test_watertight_winding_is_fixed(flip_fraction):
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.05)
    faces = mesh.faces.copy()
    flip = np.random.default_rng(RNG_SEED).random(len(faces)) < flip_fraction
    faces[flip] = faces[flip][:, ::-1]
    surface = load_object(trimesh.Trimesh(mesh.vertices + CENTRE, faces, process=False))
    assert _outward_fraction(surface, CENTRE) == 1.0
    fixed = trimesh.Trimesh(surface.mesh_vertices, surface.mesh_faces, process=False)
    assert fixed.is_winding_consistent and fixed.volume > 0


def test_open_scan_keeps_winding_unless_viewpoint_given():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.05)
    upper = sphere.faces[sphere.triangles_center[:, 2] > 0.01][:, ::-1]  # inward-wound cap
    cap = trimesh.Trimesh(sphere.vertices, upper, process=False)
    kept = load_object(cap)
    assert np.all(np.einsum("ij,ij->i", kept.points, kept.normals) < 0)  # the file's winding
    camera = np.array([0.0, 0.0, 0.5])
    seen = load_object(cap, viewpoint=camera)
    assert np.all(np.einsum("ij,ij->i", seen.points, seen.normals) > 0)
    assert np.all(np.einsum("ij,ij->i", camera - seen.points, seen.normals) > 0)


def test_multi_body_glb_keeps_every_body_with_its_transform(tmp_path):
    scene = trimesh.Scene()
    box = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.03)
    rotation = trimesh.transformations.rotation_matrix(0.7, [0, 0, 1])
    scene.add_geometry(
        box, transform=trimesh.transformations.translation_matrix([0.1, 0, 0]) @ rotation
    )
    scene.add_geometry(sphere, transform=trimesh.transformations.translation_matrix([-0.1, 0, 0]))
    path = tmp_path / "two.glb"
    scene.export(path)
    surface = load_object(path)
    on_box, on_sphere = surface.points[:, 0] > 0, surface.points[:, 0] < 0
    assert on_box.sum() > 300 and on_sphere.sum() > 300
    assert np.all(
        np.abs(surface.points[on_box, :2] - [0.1, 0]).max(axis=1) < 0.0283
    )  # 0.02 * sqrt 2
    assert np.allclose(
        np.linalg.norm(surface.points[on_sphere] - [-0.1, 0, 0], axis=1), 0.03, atol=1e-3
    )
    for mask, centre in ((on_box, [0.1, 0, 0]), (on_sphere, [-0.1, 0, 0])):
        d = np.einsum("ij,ij->i", surface.points[mask] - centre, surface.normals[mask])
        assert np.all(d > 0)
    assert len(surface.mesh_faces) == len(box.faces) + len(sphere.faces)


def test_textured_obj_with_seams_is_one_closed_outward_surface(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.04)
    path = tmp_path / "seamed.obj"
    _write_seamed_obj(
        path, sphere, invert=True
    )  # inward winding: only a merged, closed body is fixed
    surface = load_object(path)
    assert len(surface.mesh_vertices) == len(sphere.vertices)
    merged = trimesh.Trimesh(surface.mesh_vertices, surface.mesh_faces, process=False)
    assert merged.is_watertight and merged.body_count == 1 and merged.volume > 0
    assert _outward_fraction(surface, np.zeros(3)) == 1.0


def test_obj_quads_and_negative_indices(tmp_path):
    corners = np.array([[x, y, z] for x in (0, 0.05) for y in (0, 0.05) for z in (0, 0.05)])
    quads = [[1, 2, 4, 3], [5, 7, 8, 6], [1, 5, 6, 2], [3, 4, 8, 7], [1, 3, 7, 5], [2, 6, 8, 4]]
    lines = [f"v {x} {y} {z}" for x, y, z in corners]
    lines += [
        "f " + " ".join(str(i - 9) for i in q) for q in quads[:3]
    ]  # -1 = the last vertex read
    lines += ["f " + " ".join(f"{i}//{i}" for i in q) for q in quads[3:]]
    path = tmp_path / "cube.obj"
    path.write_text("\n".join(lines) + "\n")
    surface = load_object(path)
    assert len(surface.mesh_faces) == 12
    centre = np.full(3, 0.025)
    axis = np.argmax(np.abs(surface.points - centre), axis=1)  # the face each point is on
    expected = np.zeros_like(surface.normals)
    expected[np.arange(len(axis)), axis] = np.sign(
        (surface.points - centre)[np.arange(len(axis)), axis]
    )
    assert np.allclose(surface.normals, expected, atol=1e-9)


@pytest.mark.parametrize("suffix", ["stl", "off", "ply", "obj", "glb"])
def test_mesh_file_round_trip(tmp_path, suffix):
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    mesh.apply_translation(CENTRE)
    path = tmp_path / f"sphere.{suffix}"
    mesh.export(path)
    surface = load_object(path)
    assert surface.is_mesh and surface.name == path.name
    assert len(surface.mesh_vertices) == len(mesh.vertices) and len(surface.mesh_faces) == len(
        mesh.faces
    )
    assert np.allclose(
        np.sort(surface.mesh_vertices, axis=0), np.sort(mesh.vertices, axis=0), atol=1e-6
    )
    assert _outward_fraction(surface, CENTRE) == 1.0


@pytest.mark.parametrize(
    ("units", "scale", "size"), [("mm", 1.0, 50.0), ("cm", 1.0, 5.0), ("m", 2.0, 0.025)]
)
def test_units_and_scale_give_metres(units, scale, size):
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=size)
    surface = load_object(mesh, units=units, scale=scale)
    assert np.allclose(np.linalg.norm(surface.points, axis=1), 0.05, atol=5e-4)
    assert np.allclose(np.linalg.norm(surface.mesh_vertices, axis=1), 0.05, atol=1e-9)
    cloud = load_object(_sphere_cloud(1000, radius=size) - CENTRE, units=units, scale=scale)
    assert np.allclose(np.linalg.norm(cloud.points, axis=1), 0.05, atol=1e-9)


def test_mesh_explicit_voxel_size_and_max_points():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.05)
    surface = load_object(mesh, voxel_size=0.01)
    assert surface.spacing == 0.01
    cells = np.floor(surface.points / 0.01).astype(int)
    assert len(np.unique(cells, axis=0)) == surface.n_points  # one point per voxel
    capped = load_object(mesh, max_points=800)
    assert 10 <= capped.n_points <= 800


# --------------------------------------------------------------------------- point clouds


@pytest.mark.parametrize(("noise", "median_deg", "max_deg"), [(0.0, 2.0, 6.0), (0.001, 6.0, 25.0)])
def test_cylinder_cloud_normals_radial_and_outward(noise, median_deg, max_deg):
    points = _cylinder_cloud(40000)
    points = points + np.random.default_rng(1).normal(0.0, noise, points.shape)
    surface = load_object(points)
    assert not surface.is_mesh and 2000 <= surface.n_points <= 4000
    p, n = surface.points, surface.normals
    lateral = np.abs(p[:, 2]) < 0.06 - 0.01  # away from the rims
    radial = _radial(p[lateral])
    angle = _angle_deg(n[lateral], radial)
    assert np.median(angle) < median_deg and angle.max() < max_deg
    assert np.all(np.einsum("ij,ij->i", n[lateral], radial) > 0)  # outward
    caps = np.hypot(p[:, 0], p[:, 1]) < 0.04 - 0.01
    assert np.all(n[caps, 2] * np.sign(p[caps, 2]) > 0.9)


def test_partial_cylinder_cloud_oriented_toward_viewpoint():
    camera = np.array([0.5, 0.0, 0.0])
    points = _cylinder_cloud(30000, caps=False)
    visible = np.einsum("ij,ij->i", camera - points, _radial(points)) > 0.2 * np.linalg.norm(
        camera - points, axis=1
    )  # what the camera sees (not at grazing angles)
    points = points[visible] + np.random.default_rng(2).normal(0.0, 0.001, (visible.sum(), 3))
    for surface in (load_object(points, viewpoint=camera), load_object(points)):
        cos = np.einsum("ij,ij->i", surface.normals, _radial(surface.points))
        assert np.all(cos > 0)
        # 1 mm noise at a ~3 mm spacing (the half cloud gets a finer voxel for the same count).
        assert np.median(_angle_deg(surface.normals, _radial(surface.points))) < 10.0


def test_bowl_seen_from_above_faces_the_camera():
    # The inside of a hemispherical bowl: outward (out of the material) is toward its centre.
    points = _sphere_cloud(6000) - CENTRE
    points = points[points[:, 2] < -0.01]
    camera = np.array([0.0, 0.0, 0.5])
    surface = load_object(points, viewpoint=camera)
    assert np.all(np.einsum("ij,ij->i", surface.normals, -surface.points) > 0)


def test_separate_parts_each_oriented_outward():
    left, right = _sphere_cloud(2000) - CENTRE, _sphere_cloud(2000, seed=3) - CENTRE
    left[:, 0] -= 0.2
    right[:, 0] += 0.2
    surface = load_object(np.vstack([left, right]))
    for sign in (-1, 1):
        part = np.sign(surface.points[:, 0]) == sign
        centre = np.array([0.2 * sign, 0, 0])
        d = np.einsum("ij,ij->i", surface.points[part] - centre, surface.normals[part])
        assert np.all(d > 0)


def test_cloud_explicit_voxel_averages_each_voxel():
    raw = _cylinder_cloud(20000)
    surface = load_object(raw, voxel_size=0.008)
    raw_cells = {tuple(c) for c in np.floor(raw / 0.008).astype(int)}
    out_cells = [tuple(c) for c in np.floor(surface.points / 0.008).astype(int)]
    assert surface.spacing == 0.008 and surface.n_points == len(raw_cells)
    assert set(out_cells) <= raw_cells  # an average of a voxel's points stays in that voxel
    assert load_object(raw, max_points=500).n_points <= 500


def test_small_cloud_is_kept_as_is():
    raw = _sphere_cloud(1500)
    surface = load_object(raw)
    assert np.array_equal(surface.points, raw)
    gaps = cKDTree(raw).query(raw, k=2)[0][:, 1]
    assert surface.spacing == pytest.approx(np.median(gaps))
    assert _outward_fraction(surface, CENTRE) == 1.0


def _cloud_with_normals(n=1500):
    points = _sphere_cloud(n)
    return points, (points - CENTRE) / 0.05


@pytest.mark.parametrize("with_normals", [False, True])
@pytest.mark.parametrize("kind", ["xyz", "npy", "pcd-ascii", "pcd-binary", "ply"])
def test_point_cloud_file_round_trip(tmp_path, kind, with_normals):
    points, normals = _cloud_with_normals()
    if kind == "ply" and not with_normals:
        path = tmp_path / "cloud.ply"
        trimesh.PointCloud(points).export(path)
    elif kind == "ply":
        path = tmp_path / "cloud.ply"
        _write_ply_cloud(path, points, normals)
    elif kind == "xyz":
        path = tmp_path / "cloud.xyz"
        table = np.hstack([points, normals]) if with_normals else points
        body = "\n".join(" ".join(f"{v:.10g}" for v in row) for row in table)
        path.write_text("# x y z [nx ny nz]\n" + body + "\n\n")
    elif kind == "npy":
        path = tmp_path / "cloud.npy"
        np.save(path, np.hstack([points, normals]) if with_normals else points)
    else:
        path = tmp_path / "cloud.pcd"
        _write_pcd(path, points, normals if with_normals else None, binary=kind == "pcd-binary")
    surface = load_object(path)
    assert not surface.is_mesh and surface.name == path.name
    assert np.allclose(surface.points, points, atol=1e-7)  # float32 files: ~1e-8 m
    if with_normals:
        assert np.allclose(surface.normals, normals, atol=1e-6)
    else:
        assert _outward_fraction(surface, CENTRE) == 1.0


def test_pcd_drops_pcl_invalid_points(tmp_path):
    points = _sphere_cloud(500)
    points[::10] = np.nan  # PCL's marker for a missing measurement
    path = tmp_path / "organised.pcd"
    _write_pcd(path, points, None, binary=True)
    assert load_object(path).n_points == 450


# --------------------------------------------------------------------------- errors


def _error_cases(tmp_path: Path):
    (tmp_path / "empty.stl").write_bytes(b"")
    (tmp_path / "junk.stl").write_text("this is not an stl file at all")
    (tmp_path / "junk.obj").write_text("v 1 2 three\nf 1 2 3\n")
    (tmp_path / "blank.xyz").write_text("# only a comment\n\n")
    (tmp_path / "cloud.foo").write_text("1 2 3\n")
    (tmp_path / "bad.xyz").write_text("0 0 0\n1 1\n")
    np.save(tmp_path / "none.npy", np.empty((0, 3)))
    (tmp_path / "packed.pcd").write_text(
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
        "POINTS 1\nDATA binary_compressed\n"
    )
    (tmp_path / "headless.pcd").write_text("1 2 3\n4 5 6\n")
    inf_xyz = _sphere_cloud(100)
    inf_xyz[5, 1] = np.inf
    np.savetxt(tmp_path / "inf.xyz", inf_xyz)
    nan_cloud = _sphere_cloud(100)
    nan_cloud[3, 0] = np.nan
    zero_normals = np.hstack([_sphere_cloud(100), np.zeros((100, 3))])
    cloud = _sphere_cloud(200)
    return [
        (tmp_path / "missing.stl", {}, "does not exist"),
        (tmp_path, {}, "is not a file"),
        (tmp_path / "empty.stl", {}, "is empty"),
        (tmp_path / "junk.stl", {}, "no triangles or points"),
        (tmp_path / "junk.obj", {}, "cannot read"),
        (tmp_path / "blank.xyz", {}, "holds no points"),
        (tmp_path / "bad.xyz", {}, "cannot read"),
        (tmp_path / "cloud.foo", {}, "unknown object format"),
        (tmp_path / "none.npy", {}, "is empty"),
        (tmp_path / "packed.pcd", {}, "binary_compressed"),
        (tmp_path / "headless.pcd", {}, "no FIELDS/DATA"),
        (tmp_path / "inf.xyz", {}, "NaN or infinite"),
        (nan_cloud, {}, "NaN or infinite"),
        (zero_normals, {}, "zero-length normals"),
        (cloud[:5], {}, "fewer than 10"),
        (cloud * 1000.0, {}, "looks like millimetres: pass units='mm'"),
        (cloud * 5000.0, {"units": "cm"}, "looks like millimetres: pass units='mm'"),
        (cloud * 1e-3, {}, "less than 2 mm"),
        (cloud, {"units": "mm"}, "looks like metres already: pass units='m'"),
        (cloud, {"voxel_size": 1.0}, "pass a smaller voxel_size"),
        (np.zeros((20, 4)), {}, "shape (20, 4)"),
        (np.zeros(30), {}, "shape (30,)"),
        (np.zeros((2, 10, 3)), {}, "shape (2, 10, 3)"),
        (cloud.tolist(), {}, "cannot load an object from list"),
    ]


def test_every_bad_source_raises_a_one_line_error(tmp_path):
    for source, kwargs, expected in _error_cases(tmp_path):
        with pytest.raises(ObjectLoadError) as info:
            load_object(source, **kwargs)
        message = str(info.value)
        assert expected in message, (
            source if not isinstance(source, np.ndarray) else "array",
            message,
        )
        assert "\n" not in message and ":" in message  # one line: the problem, then the fix


@pytest.mark.parametrize(
    "kwargs",
    [
        {"units": "inch"},
        {"scale": 0.0},
        {"scale": float("nan")},
        {"voxel_size": -0.01},
        {"max_points": 3},
        {"max_points": 2.5},
        {"viewpoint": [1.0, 2.0]},
    ],
)
def test_bad_arguments_raise_invalid_input(kwargs):
    with pytest.raises(InvalidInputError, match="pass"):
        load_object(_sphere_cloud(100), **kwargs)


# --------------------------------------------------------------------------- real data and speed


def test_fifteen_thousand_face_obj_loads_quickly(tmp_path):
    mesh = trimesh.creation.capsule(height=0.1, radius=0.03, count=[88, 88])
    path = tmp_path / "capsule.obj"
    mesh.export(path)
    assert 14000 <= len(mesh.faces) <= 17000
    best = min(_timed(load_object, path) for _ in range(3))
    assert best < 0.3, f"loading {len(mesh.faces)} faces took {best:.3f} s"


def _timed(fn, *args) -> float:
    start = time.perf_counter()
    fn(*args)
    return time.perf_counter() - start


def test_real_ycb_can_is_metres_sized_with_outward_normals():
    path = _ycb_dir() / "MasterChefCan.obj"
    if not path.is_file():
        pytest.skip(
            f"YCB data not found at {path} (set ISF_YCB_DIR to the folder of the YCB .obj files)"
        )
    surface = load_object(path)
    diagonal = np.linalg.norm(np.ptp(surface.mesh_vertices, axis=0))
    assert 0.05 < diagonal < 0.5
    assert 2000 <= surface.n_points <= 4000
    assert _outward_fraction(surface, surface.centroid) > 0.8
    closed = trimesh.Trimesh(surface.mesh_vertices, surface.mesh_faces, process=False)
    assert closed.is_watertight and closed.volume > 0
    assert min(_timed(load_object, path) for _ in range(3)) < 0.3
