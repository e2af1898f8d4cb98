"""Collision checks against analytic depths and gaps, and against coal's exact mesh distances.

The gripper (built in code): a palm box under two prismatic fingers. Each finger is a 2 mm pad
box (its inner face is the contact surface) backed by a 1 cm body box, 2 cm wide and 4.5 cm
long. The test pose turns the gripper upside down over a 4 cm cube centred at the origin, so
with palm height ``H`` and joint value ``q`` (object frame):

* palm: x in [-4, 4] cm, |y| <= 1 cm, z in [H, H + 2 cm];
* left pad: x in [q, q + 2 mm], body: x in [q + 2 mm, q + 12 mm]; the right finger mirrors it;
* both fingers: |y| <= 1 cm, z in [H - 4.5 cm, H].
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import trimesh

from isf.collision.checker import CollisionChecker, CollisionReport, Plane
from isf.exceptions import GripperDescriptionError, InvalidInputError
from isf.gripper.model import ContactSurface, Gripper, LinkGeometry
from isf.object.surface import ObjectSurface

PAD = 0.002  # pad thickness, m
BODY = 0.01  # finger body thickness, m
LENGTH = 0.045  # finger length, m
CUBE = 0.02  # half edge of the cube object, m

JAW_XML = """<robot name="jaw">
  <link name="palm"/><link name="left"/><link name="right"/>
  <joint name="left_joint" type="prismatic"><parent link="palm"/><child link="left"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.05" effort="1" velocity="1"/></joint>
  <joint name="right_joint" type="prismatic"><parent link="palm"/><child link="right"/>
    <axis xyz="1 0 0"/><limit lower="-0.05" upper="0" effort="1" velocity="1"/>
    <mimic joint="left_joint" multiplier="-1" offset="0"/></joint>
</robot>"""


def _box(link: str, name: str, lo, hi) -> LinkGeometry:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    mesh = trimesh.creation.box(extents=hi - lo)
    mesh.apply_translation((lo + hi) / 2)
    return LinkGeometry(link=link, name=name, vertices=np.asarray(mesh.vertices),
                        faces=np.asarray(mesh.faces))


def _pad_surface(link: str, side: float) -> ContactSurface:
    y, z = np.meshgrid(np.linspace(-0.01, 0.01, 9), np.linspace(0.0, LENGTH, 19))
    points = np.c_[np.zeros(y.size), y.ravel(), z.ravel()]
    normals = np.tile([-side, 0.0, 0.0], (len(points), 1))
    return ContactSurface(name=link, link=link, points=points, normals=normals, area=0.02 * LENGTH)


def jaw_gripper() -> Gripper:
    """The palm + two (pad, body) fingers described in the module docstring."""
    model = pin.buildModelFromXML(JAW_XML, mimic=True)
    geometries = [_box("palm", "palm", (-0.04, -0.01, -0.02), (0.04, 0.01, 0.0))]
    for link, s in (("left", 1.0), ("right", -1.0)):
        for name, a, b in (("pad", 0.0, PAD), ("body", PAD, PAD + BODY)):
            lo, hi = sorted((s * a, s * b))
            geometries.append(_box(link, f"{link}_{name}", (lo, -0.01, 0.0), (hi, 0.01, LENGTH)))
    surfaces = (_pad_surface("left", 1.0), _pad_surface("right", -1.0))
    return Gripper(name="jaw", model=model, surfaces=surfaces, q_initial=np.array([0.02]),
                   geometries=tuple(geometries))


def mesh_object(mesh: trimesh.Trimesh, n: int = 3000, *, keep_mesh: bool = True) -> ObjectSurface:
    """Random surface samples of a trimesh shape with face normals, plus the mesh itself unless
    ``keep_mesh`` is False (then a bare point cloud)."""
    points, face = trimesh.sample.sample_surface(mesh, n, seed=1)
    extra = {}
    if keep_mesh:
        extra = {"mesh_vertices": np.asarray(mesh.vertices), "mesh_faces": np.asarray(mesh.faces)}
    return ObjectSurface(points=points, normals=mesh.face_normals[face],
                         spacing=float(np.sqrt(mesh.area / n)), name="test object", **extra)


def pose(height: float, shift=(0.0, 0.0)) -> np.ndarray:
    """Gripper upside down (approach -z) with its palm frame at (shift, height)."""
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[:3, 3] = [shift[0], shift[1], height]
    return T


GAP = 0.0005  # pad-to-face gap of a "touching" grasp, m


@pytest.fixture(scope="module")
def gripper() -> Gripper:
    return jaw_gripper()


@pytest.fixture(scope="module")
def cube_mesh() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=(2 * CUBE,) * 3)


@pytest.fixture(scope="module", params=["mesh", "cloud"])
def cube(request, gripper, cube_mesh) -> CollisionChecker:
    """A checker for the 4 cm cube, as a mesh and as a bare point cloud (no mesh)."""
    return CollisionChecker(gripper, mesh_object(cube_mesh, keep_mesh=request.param == "mesh"))


@pytest.fixture(scope="module", params=["mesh", "cloud"])
def cube_on_table(request, gripper, cube_mesh) -> CollisionChecker:
    obj = mesh_object(cube_mesh, keep_mesh=request.param == "mesh")
    return CollisionChecker(gripper, obj, obstacles=[Plane.table(-CUBE)])


# ------------------------------------------------------------------ analytic verdicts
def test_palm_through_the_object_collides_at_the_analytic_depth(cube):
    # palm bottom 5 mm below the cube's top face; pads 0.5 mm clear of the sides
    report = cube.check(pose(CUBE - 0.005), [CUBE + GAP])
    assert not report.collision_free
    assert report.penetration == pytest.approx(0.005, abs=1e-3)
    assert report.colliding_links == ("palm",)
    assert report.obstacle == "object"
    assert report.clearance == 0.0
    assert report.link_depths["palm"] == report.penetration
    assert report.link_depths["left"] == report.link_depths["right"] == 0.0


def test_fingers_through_the_object_collide_at_the_analytic_depth(cube):
    # each pad face 5 mm inside a side face of the cube
    report = cube.check(pose(0.03), [CUBE - 0.005])
    assert not report.collision_free
    assert report.penetration == pytest.approx(0.005, abs=1e-3)
    assert report.colliding_links == ("left", "right")
    assert report.obstacle == "object"


@pytest.mark.parametrize("offset", [GAP, -GAP])
def test_pads_just_touching_are_no_collision(cube, offset):
    # pads 0.5 mm off (or into) the cube's sides; the finger bodies sit 2 mm behind the pads,
    # the palm 10 mm above the cube: the non-contact geometry is PAD + offset away
    report = cube.check(pose(0.03), [CUBE + offset])
    assert report.collision_free, report
    assert report.penetration == pytest.approx(max(0.0, -offset), abs=2e-4)
    assert report.clearance == pytest.approx(PAD + offset, abs=2e-4)
    assert report.colliding_links == () and report.obstacle is None


def test_finger_below_the_table_is_rejected_with_the_analytic_depth(cube_on_table):
    # palm 2 mm above the cube, finger tips 3 mm below the table the cube stands on
    report = cube_on_table.check(pose(CUBE + 0.002), [CUBE + GAP])
    assert not report.collision_free
    assert report.obstacle == "table"
    exact = LENGTH - 0.002 - 2 * CUBE  # from the vertices: exact
    assert report.penetration == pytest.approx(exact, abs=1e-9)
    assert report.colliding_links == ("left", "right")
    assert report.clearance == 0.0


def test_table_clearance_counts_the_contact_geometry_too(cube_on_table):
    # tips 5 mm above the table; bodies 2.5 mm from the cube: clearance is the bodies'
    report = cube_on_table.check(pose(0.03), [CUBE + GAP])
    assert report.collision_free and report.clearance == pytest.approx(PAD + GAP, abs=2e-4)
    # open the jaw: bodies 1.2 cm away, so the pad tips over the table (5 mm) decide
    report = cube_on_table.check(pose(0.03), [CUBE + 0.01])
    assert report.collision_free and report.clearance == pytest.approx(0.005, abs=1e-9)


@pytest.mark.parametrize(("height", "shift", "q", "gap"), [
    (0.05, (0.0, 0.0), 0.03, 0.012),  # jaw open around the cube: bodies 12 mm off its sides
    (0.03, (0.0, 0.05), CUBE + GAP, float(np.hypot(0.02, PAD + GAP))),  # beside: bodies nearest
    (0.3, (0.0, 0.0), CUBE + GAP, float(np.hypot(0.3 - LENGTH - CUBE, PAD + GAP))),  # far above
])
def test_clearly_separated_grippers_report_the_analytic_gap(cube, height, shift, q, gap):
    report = cube.check(pose(height, shift), [q])
    assert report.collision_free and report.penetration == 0.0
    tol = 2e-4 if gap < 0.02 else 1.5e-3  # beyond 2 cm clearance comes from coarse subsets
    assert report.clearance == pytest.approx(gap, abs=tol)


@pytest.mark.parametrize("keep_mesh", [True, False])
def test_curved_object_depths_and_gaps(gripper, keep_mesh):
    R = 0.02
    ball = trimesh.creation.icosphere(subdivisions=4, radius=R)
    sphere = mesh_object(ball, 4000, keep_mesh=keep_mesh)
    checker = CollisionChecker(gripper, sphere)
    report = checker.check(pose(R - 0.004), [R + GAP])  # palm 4 mm into the sphere's top
    assert not report.collision_free and report.colliding_links == ("palm",)
    assert report.penetration == pytest.approx(0.004, abs=1e-3)
    for offset in (GAP, -GAP):  # pads tangent to the sphere, 0.5 mm off or in
        report = checker.check(pose(0.03), [R + offset])
        assert report.collision_free
        assert report.penetration == pytest.approx(max(0.0, -offset), abs=3e-4)
        assert report.clearance == pytest.approx(PAD + offset, abs=3e-4)


@pytest.mark.parametrize("keep_mesh", [True, False])
def test_thin_feature_between_gripper_samples_is_found(gripper, keep_mesh):
    # A 1 mm plate, 3 cm square, standing in the x-z plane: its top edge is 5 mm deep in the
    # palm. Palm samples inside the plate can be at most 0.5 mm deep; the depth comes from the
    # plate's own points inside the palm.
    plate = trimesh.creation.box(extents=(0.03, 0.001, 0.03))
    checker = CollisionChecker(gripper, mesh_object(plate, 3000, keep_mesh=keep_mesh))
    report = checker.check(pose(0.015 - 0.005), [0.03])
    assert not report.collision_free and report.colliding_links == ("palm",)
    assert report.penetration == pytest.approx(0.005, abs=5e-4)


# ------------------------------------------------------------------ independent references
def _boxes(gripper: Gripper) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """(link, name, lo, hi) of every box element, link frame."""
    return [(g.link, g.name, g.vertices.min(axis=0), g.vertices.max(axis=0))
            for g in gripper.geometries]


def _link_pose(T: np.ndarray, link: str, q: float) -> np.ndarray:
    """T_object_link of the jaw, written out by hand (left slides +x by q, right -x by q)."""
    shift = np.eye(4)
    shift[0, 3] = {"palm": 0.0, "left": q, "right": -q}[link]
    return T @ shift


def _deepest(R, p, lo, hi) -> float:
    """Exact depth of the deepest point of either surface inside the other solid: a box
    [lo, hi] posed by (R, p) against the cube [-CUBE, CUBE]^3, by linear programs (negative
    when apart). One LP per face of each box: maximise s subject to the point on that face and
    s below its distance to every face plane of the other box."""
    from scipy.optimize import linprog

    best = -np.inf
    for j in range(3):  # a face of the gripper box, inside the cube
        for v in (lo[j], hi[j]):
            bounds = [(lo[i], hi[i]) if i != j else (v, v) for i in range(3)] + [(None, None)]
            A = [[*R[i], 1.0] for i in range(3)] + [[*(-R[i]), 1.0] for i in range(3)]
            b = [CUBE - p[i] for i in range(3)] + [CUBE + p[i] for i in range(3)]
            res = linprog([0, 0, 0, -1], A_ub=A, b_ub=b, bounds=bounds, method="highs")
            best = max(best, -res.fun)
    for j in range(3):  # a face of the cube, inside the gripper box
        for v in (-CUBE, CUBE):
            bounds = [(-CUBE, CUBE) if i != j else (v, v) for i in range(3)] + [(None, None)]
            A = [[*(-R[:, i]), 1.0] for i in range(3)] + [[*R[:, i], 1.0] for i in range(3)]
            b = [-(R[:, i] @ p) - lo[i] for i in range(3)] + [hi[i] + R[:, i] @ p for i in range(3)]
            res = linprog([0, 0, 0, -1], A_ub=A, b_ub=b, bounds=bounds, method="highs")
            best = max(best, -res.fun)
    return best


def _random_poses(seed: int, n: int, radius: tuple[float, float]):
    """n random (T, q) with the palm frame at a random direction and distance from the cube."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        axis = rng.normal(size=3)
        R = trimesh.transformations.rotation_matrix(rng.uniform(0, np.pi), axis)[:3, :3]
        direction = rng.normal(size=3)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = direction / np.linalg.norm(direction) * rng.uniform(*radius)
        yield T, float(rng.uniform(0.0, 0.04))


@pytest.fixture(scope="module")
def exact_poses(gripper):
    """Random poses with the exact deepest penetration of the whole gripper into the cube."""
    out = []
    for T, q in _random_poses(7, 24, (0.025, 0.065)):
        depth = 0.0
        for link, _, lo, hi in _boxes(gripper):
            M = _link_pose(T, link, q)
            corners = trimesh.bounds.corners(np.array([lo, hi])) @ M[:3, :3].T + M[:3, 3]
            if np.all(corners.max(axis=0) > -CUBE) and np.all(corners.min(axis=0) < CUBE):
                depth = max(depth, _deepest(M[:3, :3], M[:3, 3], lo, hi))
        out.append((T, q, depth))
    return out


def test_penetration_matches_exact_depths(cube, exact_poses):
    tol = cube.tolerance
    n_deep = 0
    for T, q, exact in exact_poses:
        report = cube.check(T, [q])
        assert report.penetration <= exact + 1e-9  # never reads deeper than the truth
        if exact <= 0.006:
            assert report.penetration >= exact - 1e-3, (exact, report)
        else:
            n_deep += 1
            assert report.penetration >= 0.8 * exact, (exact, report)
        if exact <= tol:
            assert report.collision_free
        elif exact > tol + 1e-3:
            assert not report.collision_free
    assert 3 <= n_deep <= len(exact_poses) - 8  # the poses cover both regimes


def _coal_bvh(vertices, faces):
    import coal

    model = coal.BVHModelOBBRSS()
    model.beginModel(len(faces), len(vertices))
    model.addVertices(np.ascontiguousarray(vertices, dtype=np.float64))
    model.addTriangles(np.ascontiguousarray(faces, dtype=np.int64))
    model.endModel()
    return model


def test_clearance_matches_coal_mesh_distances(cube, gripper, cube_mesh, exact_poses):
    import coal

    cube_bvh = _coal_bvh(cube_mesh.vertices, cube_mesh.faces)
    spacing = cube.object.spacing
    areas = [trimesh.Trimesh(g.vertices, g.faces).area for g in gripper.geometries
             if not g.name.endswith("_pad")]
    element_spacing = max(np.sqrt(a / min(800, a / 1e-6)) for a in areas)  # 1 mm, 800 at most
    checked = 0
    for T, q, exact in exact_poses:
        if exact > 0:
            continue
        distance = np.inf
        for g in gripper.geometries:
            if g.name.endswith("_pad"):  # contact elements do not count
                continue
            M = _link_pose(T, g.link, q)
            distance = min(distance, coal.distance(
                _coal_bvh(g.vertices, g.faces), coal.Transform3s(M[:3, :3], M[:3, 3]), cube_bvh,
                coal.Transform3s(), coal.DistanceRequest(), coal.DistanceResult()))
        report = cube.check(T, [q])
        # never below the true distance for a mesh; above it by at most half the sample spacing
        # of the coarsest non-contact element (the documented bound), plus half the object's
        # point spacing for a point cloud
        assert report.clearance >= distance - (1e-9 if cube.object.is_mesh else spacing / 2)
        assert report.clearance <= distance + element_spacing / 2 + (0 if cube.object.is_mesh else spacing / 2)
        checked += 1
    assert checked >= 5


# ------------------------------------------------------------------ other element kinds
def _with_palm(gripper: Gripper, palm: trimesh.Trimesh) -> Gripper:
    geometries = (LinkGeometry("palm", "palm", np.asarray(palm.vertices), np.asarray(palm.faces)),
                  *gripper.geometries[1:])
    return Gripper(name="jaw", model=gripper.model, surfaces=gripper.surfaces,
                   q_initial=gripper.q_initial, geometries=geometries)


def test_non_convex_palm_finds_a_thin_feature_inside_it(gripper):
    # An L-shaped palm: the usual 8 x 2 x 2 cm block plus a 2 x 2 x 2 cm stub on top of one
    # end. The 1 mm plate's edge is 5 mm deep in the block part (as in the thin-feature test).
    from shapely.geometry import Polygon

    outline = Polygon([(-0.04, -0.02), (0.04, -0.02), (0.04, 0.0), (-0.02, 0.0), (-0.02, 0.02),
                       (-0.04, 0.02)])  # (x, z) of the L
    palm = trimesh.creation.extrude_polygon(outline, 0.02)  # extruded along +z from 0
    palm.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))  # -> y
    palm.apply_translation((0.0, 0.01, 0.0))  # |y| <= 1 cm
    assert palm.is_watertight and not palm.is_convex
    jaw = _with_palm(gripper, palm)
    plate = trimesh.creation.box(extents=(0.03, 0.001, 0.03))
    report = CollisionChecker(jaw, mesh_object(plate, 3000)).check(pose(0.015 - 0.005), [0.03])
    assert not report.collision_free and report.colliding_links == ("palm",)
    assert report.penetration == pytest.approx(0.005, abs=1e-3)


def test_open_palm_sheet_still_collides_through_its_surface(gripper, cube_mesh):
    # The palm as a single open square sheet at z = -1 cm (no inside): only its own points
    # can penetrate. Lowered 5 mm into the cube it is 5 mm deep.
    sheet = trimesh.Trimesh([[-0.04, -0.01, -0.01], [0.04, -0.01, -0.01], [0.04, 0.01, -0.01],
                             [-0.04, 0.01, -0.01]], [[0, 1, 2], [0, 2, 3]])
    checker = CollisionChecker(_with_palm(gripper, sheet), mesh_object(cube_mesh))
    report = checker.check(pose(CUBE - 0.005 - 0.01), [CUBE + GAP])
    assert not report.collision_free and report.colliding_links == ("palm",)
    assert report.penetration == pytest.approx(0.005, abs=5e-4)


def test_surfaces_on_no_geometry_make_the_whole_link_contact(gripper, cube_mesh):
    # Contact points 1 mm in front of the pads (e.g. taken from visual meshes): both finger
    # elements then count as contact, so only the palm (1 cm above the cube) sets clearance.
    moved = tuple(ContactSurface(s.name, s.link, s.points + 0.001 * s.normals, s.normals, s.area)
                  for s in gripper.surfaces)
    jaw = Gripper(name="jaw", model=gripper.model, surfaces=moved, q_initial=gripper.q_initial,
                  geometries=gripper.geometries)
    report = CollisionChecker(jaw, mesh_object(cube_mesh)).check(pose(0.03), [CUBE + GAP])
    assert report.clearance == pytest.approx(0.01, abs=2e-4)


# ------------------------------------------------------------------ inputs and values
def test_plane_normalises_its_normal_and_offset():
    plane = Plane((0.0, 0.0, 2.0), 1.0, name="shelf")
    assert np.allclose(plane.normal, (0, 0, 1)) and plane.offset == pytest.approx(0.5)
    assert np.allclose(plane.height(np.array([[0.0, 0.0, 0.5], [1.0, 2.0, 0.2]])), [0.0, -0.3])
    table = Plane.table(-0.1)
    assert table.name == "table"
    assert table.height(np.array([[0.0, 0.0, 0.0]]))[0] == pytest.approx(0.1)


@pytest.mark.parametrize("normal", [(0.0, 0.0, 0.0), (1.0, 0.0), (np.nan, 0.0, 1.0)])
def test_bad_plane_normal_is_rejected(normal):
    with pytest.raises(InvalidInputError, match="normal"):
        Plane(normal, 0.0)


def test_bad_inputs_are_rejected(gripper, cube_mesh):
    obj = mesh_object(cube_mesh, 500, keep_mesh=False)
    with pytest.raises(InvalidInputError, match="tolerance"):
        CollisionChecker(gripper, obj, tolerance=-0.001)
    with pytest.raises(InvalidInputError, match="Plane"):
        CollisionChecker(gripper, obj, obstacles=[(0, 0, 1, 0)])
    bare = Gripper(name="bare", model=gripper.model, surfaces=gripper.surfaces,
                   q_initial=gripper.q_initial)
    with pytest.raises(GripperDescriptionError, match="no link geometry"):
        CollisionChecker(bare, obj)
    checker = CollisionChecker(gripper, obj)
    with pytest.raises(InvalidInputError, match="4x4"):
        checker.check(np.eye(3), [0.02])
    with pytest.raises(InvalidInputError, match="rigid"):
        checker.check(2 * np.eye(4), [0.02])
    with pytest.raises(InvalidInputError, match="1 finite joint"):
        checker.check(np.eye(4), [0.02, 0.01])


def test_report_is_plain_values(cube):
    report = cube.check(pose(CUBE - 0.005), [CUBE + GAP])
    assert isinstance(report, CollisionReport)
    assert type(report.penetration) is float and type(report.clearance) is float
    assert isinstance(report.collision_free, bool)


# ------------------------------------------------------------------ brute-force agreement
BALL = 0.02  # radius of the sphere object, m


def _box_surface_points(lo, hi, spacing: float = 2.5e-4) -> np.ndarray:
    """A dense grid of points on the six faces of the box [lo, hi], link frame."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    out = []
    for axis in range(3):
        u, v = [k for k in range(3) if k != axis]
        a = np.linspace(lo[u], hi[u], max(2, int(np.ceil((hi[u] - lo[u]) / spacing)) + 1))
        b = np.linspace(lo[v], hi[v], max(2, int(np.ceil((hi[v] - lo[v]) / spacing)) + 1))
        A, B = np.meshgrid(a, b)
        for w in (lo[axis], hi[axis]):
            p = np.empty((A.size, 3))
            p[:, u], p[:, v], p[:, axis] = A.ravel(), B.ravel(), w
            out.append(p)
    return np.concatenate(out)


def _brute_depths(gripper: Gripper, T: np.ndarray, q: float, ball: np.ndarray) -> dict[str, float]:
    """Deepest point of each link's boxes inside the sphere, or of the sphere inside them:
    dense box-surface grids against the sphere's exact signed distance, and dense sphere points
    against the boxes' face planes (both 0.25 mm apart)."""
    depth: dict[str, float] = {}
    for link, _, lo, hi in _boxes(gripper):
        M = _link_pose(T, link, q)
        if np.linalg.norm(M[:3, 3]) > 0.2:
            continue
        pts = _box_surface_points(lo, hi) @ M[:3, :3].T + M[:3, 3]
        d = float(max(0.0, (BALL - np.linalg.norm(pts, axis=1)).max()))
        local = (ball - M[:3, 3]) @ M[:3, :3]  # sphere points in the link frame
        inside = np.minimum(local - lo, hi - local).min(axis=1)
        d = max(d, float(max(0.0, inside.max())))
        depth[link] = max(depth.get(link, 0.0), d)
    return depth


def test_verdicts_agree_with_a_brute_force_reference_on_a_sphere(gripper):
    # Grasp-like poses around a 2 cm sphere: the jaw closed to various widths at various
    # heights, turned a little, so the pads, bodies and palm meet the sphere at 0-5 mm depth.
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=BALL)
    checker = CollisionChecker(gripper, mesh_object(sphere, 4000))
    ball = trimesh.sample.sample_surface_even(sphere, 60000, seed=3)[0]
    ball *= BALL / np.linalg.norm(ball, axis=1, keepdims=True)
    rng = np.random.default_rng(11)
    tol = checker.tolerance
    compared = colliding = 0
    for _ in range(14):
        T = pose(rng.uniform(BALL - 0.006, BALL + 0.004), rng.uniform(-0.004, 0.004, 2))
        turn = trimesh.transformations.rotation_matrix(rng.uniform(-0.15, 0.15), rng.normal(size=3))
        T = T @ turn
        q = rng.uniform(BALL - 0.005, BALL + 0.002)
        brute = _brute_depths(gripper, T, q, ball)
        report = checker.check(T, [q])
        assert report.penetration == pytest.approx(max(brute.values()), abs=6e-4), (brute, report)
        assert report.penetration == max(report.link_depths.values())
        for link, d in brute.items():
            assert report.link_depths[link] == pytest.approx(d, abs=6e-4), (link, d, report)
            if abs(d - tol) < 3e-4:  # too close to call for sampled surfaces
                continue
            compared += 1
            colliding += d > tol
            assert (link in report.colliding_links) == (d > tol), (link, d, report)
    assert compared >= 30 and 5 <= colliding <= compared - 10  # both verdicts are exercised


def test_check_many_matches_single_checks(cube):
    poses = [pose(CUBE - 0.005), pose(0.03), pose(0.05, (0.0, 0.01))]
    q = np.array([[CUBE + GAP], [CUBE - 0.005], [0.03]])
    many = cube.check_many(np.array(poses), q)
    assert many == [cube.check(T, j) for T, j in zip(poses, q)]
    with pytest.raises(InvalidInputError, match="check_many"):
        cube.check_many(np.array(poses), q[:2])
