"""Generate the three grippers bundled with isf (URDF + binary STL meshes).

Run from the repository root::

    python scripts/make_grippers.py            # writes grippers/<name>/...
    python scripts/make_grippers.py --out DIR  # writes DIR/<name>/...

The output is deterministic: re-running gives byte-identical files. After
writing, every URDF is loaded back with Pinocchio (``mimic=True``) and checked
numerically (joint counts, mesh orientation, the paper gripper's groove
geometry); the script exits non-zero if a check fails.

Geometry, frames and numbers are documented in ``docs/bundled-grippers.md``.
All lengths are metres, angles radians.

Common frame convention: the root link ``palm`` has its origin at the centre
of the palm's top face, +z is the approach direction (fingers point along +z).
Parallel grippers close along y; the ``left`` finger is on the +y side.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import trimesh

ISF_NS = "urn:isf:gripper:1"
REPO_ROOT = Path(__file__).resolve().parent.parent

# ---------------------------------------------------------------- constants
# paper-parallel (SMC LEHF20K2 with customised grooved fingertips)
PAPER_GROOVE_RADIUS = 0.008  # radius of the concave cylindrical groove
PAPER_GROOVE_HALF_ARC = math.radians(55.0)  # groove spans +-55 deg about the closing direction
PAPER_GROOVE_LENGTH = 0.016  # groove length along x
PAPER_TIP_HEIGHT = 0.06  # z of the groove axis (fingertip height)
PAPER_ARC_SEGMENTS = 32  # groove mesh: quads along the arc
PAPER_LENGTH_SEGMENTS = 16  # groove mesh: quads along x
PAPER_Q_LIMITS = (0.005, 0.015)  # q = half jaw width (d in [1, 3] cm)
PAPER_Q_INITIAL = 0.01  # d0 = 2 cm
PAPER_TIP_BACK = 0.002  # fingertip block back face, y behind the groove bottom (link frame)
PAPER_BODY = ((-0.008, 0.008), (0.002, 0.008), (0.0, 0.068))  # finger body box (x, y, z ranges)
PAPER_PALM = ((-0.016, 0.016), (-0.032, 0.032), (-0.04, 0.0))

# flat-parallel
FLAT_PAD = 0.02  # pad side length (square pad)
FLAT_PAD_HEIGHT = 0.08  # z of the pad centre
FLAT_Q_LIMITS = (0.0, 0.04)  # q = half jaw width (width 0 - 8 cm)
FLAT_Q_INITIAL = 0.04  # fully open
FLAT_TIP_DEPTH = 0.01  # fingertip box thickness along y; its inner face y = 0 is the pad
FLAT_TIP = (
    (-FLAT_PAD / 2, FLAT_PAD / 2),
    (0.0, FLAT_TIP_DEPTH),
    (FLAT_PAD_HEIGHT - FLAT_PAD / 2, FLAT_PAD_HEIGHT + FLAT_PAD / 2),
)
FLAT_BODY = ((-0.01, 0.01), (0.003, 0.013), (0.0, 0.07))  # finger body, 3 mm behind the pad plane
FLAT_PALM = ((-0.02, 0.02), (-0.06, 0.06), (-0.04, 0.0))

# three-finger
HAND_FINGER_ANGLES_DEG = (0.0, 120.0, 240.0)
HAND_PALM_RADIUS = 0.05
HAND_PALM_THICKNESS = 0.03  # palm disk spans z in [-0.03, 0]
HAND_BASE_RADIUS = 0.04  # distance of the proximal joints from the palm axis
HAND_BASE_HEIGHT = 0.01  # z of the proximal joints
HAND_PROXIMAL_LENGTH = 0.05  # proximal joint -> distal joint
HAND_PROXIMAL_RADIUS = 0.008  # proximal link: capsule radius
HAND_DISTAL_BOX = ((-0.007, 0.007), (-0.008, 0.008), (0.0, 0.035))  # distal link body
HAND_PAD_CENTRE_Z = 0.02  # pad centre along the distal link
HAND_PAD_SIZE = (0.014, 0.018)  # pad extent along (y, z) of the distal link frame
HAND_PAD_SPHERE_RADIUS = 0.05  # pad is a spherical cap of this radius (slightly convex)
HAND_PAD_APEX = 0.0085  # pad apex lies at x = -HAND_PAD_APEX (1.5 mm proud of the body)
HAND_PAD_SEGMENTS = (10, 12)  # pad mesh quads along (y, z)
HAND_PROXIMAL_LIMITS = (-0.3, 1.2)
HAND_DISTAL_LIMITS = (0.0, 1.4)
HAND_INITIAL = (-0.2, 0.2)  # open pose: pads face the palm axis horizontally
HAND_TCP_HEIGHT = 0.079  # tool-centre point on the palm axis, at the pads' centres at HAND_INITIAL

EFFORT, VELOCITY = 20.0, 0.5  # nominal URDF <limit> attributes (unused by isf)


# -------------------------------------------------------------- XML helpers
def _num(value: float) -> str:
    """A float as short, deterministic text (12 significant digits, no ``-0``)."""
    text = format(float(value), ".12g")
    return "0" if text in ("-0", "0") else text


def _vec(values) -> str:
    return " ".join(_num(v) for v in values)


def _origin(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> str:
    return f'<origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>'


@dataclass
class Part:
    """One geometry element of a link, written as <collision> and <visual>."""

    name: str
    geometry: str  # the inner element of <geometry>
    origin: str = field(default_factory=_origin)
    material: str = "grey"
    visual: bool = True


@dataclass
class Link:
    name: str
    parts: list[Part]


@dataclass
class Joint:
    name: str
    type: str
    parent: str
    child: str
    xyz: tuple
    rpy: tuple
    axis: tuple
    limits: tuple
    mimic: str | None = None


def _box_part(name: str, ranges, material: str = "grey") -> Part:
    """A URDF ``<box>`` part; ``ranges`` = ((x0, x1), (y0, y1), (z0, z1)) in the link frame."""
    lo, hi = np.array(ranges, dtype=float).T
    return Part(name, f'<box size="{_vec(hi - lo)}"/>', _origin((lo + hi) / 2), material)


def _mirror_ranges(ranges):
    """Box ranges mirrored y -> -y."""
    (y0, y1) = ranges[1]
    return (ranges[0], (-y1, -y0), ranges[2])


MATERIALS = {
    "dark": (0.25, 0.25, 0.28, 1.0),
    "grey": (0.6, 0.6, 0.62, 1.0),
    "pad": (0.85, 0.15, 0.12, 1.0),
}


def _link_xml(link: Link) -> list[str]:
    lines = [f'  <link name="{link.name}">']
    for part in link.parts:
        if part.visual:
            lines += [
                f'    <visual name="{part.name}">',
                f"      {part.origin}",
                f"      <geometry>{part.geometry}</geometry>",
                f'      <material name="{part.material}"/>',
                "    </visual>",
            ]
    for part in link.parts:
        lines += [
            f'    <collision name="{part.name}">',
            f"      {part.origin}",
            f"      <geometry>{part.geometry}</geometry>",
            "    </collision>",
        ]
    lines.append("  </link>")
    return lines


def _joint_xml(joint: Joint) -> list[str]:
    lo, hi = joint.limits
    lines = [
        f'  <joint name="{joint.name}" type="{joint.type}">',
        f'    <parent link="{joint.parent}"/>',
        f'    <child link="{joint.child}"/>',
        f"    {_origin(joint.xyz, joint.rpy)}",
        f'    <axis xyz="{_vec(joint.axis)}"/>',
        f'    <limit lower="{_num(lo)}" upper="{_num(hi)}" effort="{_num(EFFORT)}" '
        f'velocity="{_num(VELOCITY)}"/>',
    ]
    if joint.mimic:
        lines.append(f'    <mimic joint="{joint.mimic}" multiplier="1" offset="0"/>')
    lines.append("  </joint>")
    return lines


def _robot_xml(name: str, comment: str, links, joints, isf_lines) -> str:
    lines = [
        '<?xml version="1.0"?>',
        f"<!-- Generated by scripts/make_grippers.py; do not edit. {comment} -->",
        f'<robot name="{name}" xmlns:isf="{ISF_NS}">',
    ]
    for mat, rgba in MATERIALS.items():
        lines.append(f'  <material name="{mat}"><color rgba="{_vec(rgba)}"/></material>')
    for link in links:
        lines += _link_xml(link)
    for joint in joints:
        lines += _joint_xml(joint)
    lines += [f"  {line}" for line in isf_lines]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def _gripper_tag(tcp_height: float) -> str:
    """The ``<isf:gripper>`` tag: palm, approach +z, the tool-centre point on the palm axis
    at ``tcp_height`` (between the fingertips), axes those of the palm."""
    return (f'<isf:gripper palm_link="palm" approach="0 0 1" tcp_link="palm" '
            f'tcp_origin="{_vec((0.0, 0.0, tcp_height))}"/>')


def _mesh(filename: str) -> str:
    return f'<mesh filename="meshes/{filename}"/>'


# ------------------------------------------------------------- mesh helpers
def _grid_sheet(points: np.ndarray) -> trimesh.Trimesh:
    """Open quad-grid sheet from a (nu+1, nv+1, 3) vertex grid, two triangles per quad.

    Triangles wind (u, v) -> (u+1, v) -> (u+1, v+1), so the face normal is
    d/du x d/dv of the grid parametrisation.
    """
    nu, nv = points.shape[0] - 1, points.shape[1] - 1
    idx = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return trimesh.Trimesh(points.reshape(-1, 3), faces, process=False)


def _orient(mesh: trimesh.Trimesh, towards: np.ndarray) -> trimesh.Trimesh:
    """Flip the winding of an open sheet if its normals point away from ``towards``."""
    mean_dir = np.mean(np.einsum("ij,ij->i", mesh.face_normals, towards - mesh.triangles_center))
    if mean_dir < 0:
        mesh = trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], process=False)
    return mesh


def _mirror_y(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Mirror y -> -y, reversing the winding so normals stay outward."""
    vertices = mesh.vertices * np.array([1.0, -1.0, 1.0])
    return trimesh.Trimesh(vertices, mesh.faces[:, ::-1], process=False)


def _groove_angles() -> np.ndarray:
    return np.linspace(-PAPER_GROOVE_HALF_ARC, PAPER_GROOVE_HALF_ARC, PAPER_ARC_SEGMENTS + 1)


def _paper_groove_sheet() -> trimesh.Trimesh:
    """Left groove surface in the left finger frame, normals towards the groove axis.

    The groove axis is the line y = -R, z = PAPER_TIP_HEIGHT (parallel to x);
    the groove bottom (phi = 0) lies at y = 0.
    """
    r = PAPER_GROOVE_RADIUS
    phi = _groove_angles()
    x = np.linspace(-PAPER_GROOVE_LENGTH / 2, PAPER_GROOVE_LENGTH / 2, PAPER_LENGTH_SEGMENTS + 1)
    P, X = np.meshgrid(phi, x, indexing="ij")
    grid = np.stack([X, -r + r * np.cos(P), PAPER_TIP_HEIGHT + r * np.sin(P)], axis=-1)
    sheet = _grid_sheet(grid)
    return _orient(sheet, np.array([0.0, -r, PAPER_TIP_HEIGHT]))


def _paper_tip_block() -> trimesh.Trimesh:
    """Closed fingertip solid of the left finger: groove in front, flat back at y = PAPER_TIP_BACK.

    A prism along x whose (y, z) profile is bounded by the groove arc and the
    back line; the arc vertices coincide with the groove sheet's.
    """
    r, half = PAPER_GROOVE_RADIUS, PAPER_GROOVE_LENGTH / 2
    phi = _groove_angles()
    front = np.stack([-r + r * np.cos(phi), PAPER_TIP_HEIGHT + r * np.sin(phi)], 1)
    back = np.stack([np.full_like(phi, PAPER_TIP_BACK), front[:, 1]], 1)
    n = len(phi)
    # vertex blocks: front(-x), front(+x), back(-x), back(+x)
    yz = np.concatenate([front, front, back, back])
    xs = np.repeat([-half, half, -half, half], n)
    vertices = np.column_stack([xs, yz])
    F0, F1, B0, B1 = (np.arange(n) + k * n for k in range(4))

    def quad(a, b, c, d):  # counter-clockwise seen from outside
        return [[a, b, c], [a, c, d]]

    faces = []
    for i in range(n - 1):
        j = i + 1
        faces += quad(F0[i], F1[i], F1[j], F0[j])  # groove face
        faces += quad(B0[i], B0[j], B1[j], B1[i])  # back face
        faces += quad(F0[i], F0[j], B0[j], B0[i])  # -x end
        faces += quad(F1[i], B1[i], B1[j], F1[j])  # +x end
    faces += quad(F0[0], B0[0], B1[0], F1[0])  # bottom wall (lower lip)
    faces += quad(F0[-1], F1[-1], B1[-1], B0[-1])  # top wall (upper lip)
    return trimesh.Trimesh(vertices, np.array(faces), process=False)


def _hand_pad_sheet() -> trimesh.Trimesh:
    """Slightly convex fingertip pad in the distal link frame, normals towards -x (palm axis)."""
    rs = HAND_PAD_SPHERE_RADIUS
    centre = np.array([-HAND_PAD_APEX + rs, 0.0, HAND_PAD_CENTRE_Z])
    (sy, sz), (ny, nz) = HAND_PAD_SIZE, HAND_PAD_SEGMENTS
    y = np.linspace(-sy / 2, sy / 2, ny + 1)
    z = np.linspace(-sz / 2, sz / 2, nz + 1)
    Y, Z = np.meshgrid(y, z, indexing="ij")
    X = -np.sqrt(rs**2 - Y**2 - Z**2)
    grid = np.stack([X, Y, Z], axis=-1) + centre
    return _orient(_grid_sheet(grid), centre + np.array([-2 * rs, 0.0, 0.0]))


def _box_mesh(ranges) -> trimesh.Trimesh:
    lo, hi = np.array(ranges, dtype=float).T
    return trimesh.creation.box(
        extents=hi - lo, transform=trimesh.transformations.translation_matrix((lo + hi) / 2)
    )


# ----------------------------------------------------------------- grippers
@dataclass
class GripperFiles:
    name: str
    urdf: str
    meshes: dict[str, trimesh.Trimesh]


def _parallel_joints(limits) -> list[Joint]:
    """Left finger slides along +y by q; the right one mimics it (multiplier 1) along -y."""
    zero = (0.0, 0.0, 0.0)
    left = Joint("left_finger_joint", "prismatic", "palm", "left_finger", zero, zero,
                 axis=(0, 1, 0), limits=limits)  # fmt: skip
    right = Joint("right_finger_joint", "prismatic", "palm", "right_finger", zero, zero,
                  axis=(0, -1, 0), limits=limits, mimic="left_finger_joint")  # fmt: skip
    return [left, right]


def paper_parallel() -> GripperFiles:
    """The paper's parallel-jaw gripper with concave cylindrical fingertip grooves."""
    groove_left = _paper_groove_sheet()
    tip_left = _paper_tip_block()
    meshes = {
        "left_groove.stl": groove_left,
        "right_groove.stl": _mirror_y(groove_left),
        "left_tip.stl": tip_left,
        "right_tip.stl": _mirror_y(tip_left),
    }
    links = [Link("palm", [_box_part("palm_body", PAPER_PALM, "dark")])]
    for side, body in (("left", PAPER_BODY), ("right", _mirror_ranges(PAPER_BODY))):
        links.append(
            Link(
                f"{side}_finger",
                [
                    _box_part(f"{side}_body", body),
                    Part(f"{side}_tip", _mesh(f"{side}_tip.stl")),
                    Part(f"{side}_pad", _mesh(f"{side}_groove.stl"), material="pad", visual=False),
                ],
            )
        )
    isf = [
        _gripper_tag(PAPER_TIP_HEIGHT),
        '<isf:contact name="left_pad" link="left_finger" geometry="left_pad" points="256"/>',
        '<isf:contact name="right_pad" link="right_finger" geometry="right_pad" points="256"/>',
        f'<isf:initial joint="left_finger_joint" value="{_num(PAPER_Q_INITIAL)}"/>',
        '<isf:closing joint="left_finger_joint" sign="-1"/>',
    ]
    urdf = _robot_xml(
        "paper-parallel",
        "Parallel jaw with grooved fingertips (ISF paper, Fig. 3).",
        links,
        _parallel_joints(PAPER_Q_LIMITS),
        isf,
    )
    return GripperFiles("paper-parallel", urdf, meshes)


def flat_parallel() -> GripperFiles:
    """A parallel-jaw gripper with flat square pads, selected by a normal cone."""
    links = [Link("palm", [_box_part("palm_body", FLAT_PALM, "dark")])]
    for side, mirror in (("left", lambda r: r), ("right", _mirror_ranges)):
        links.append(
            Link(
                f"{side}_finger",
                [
                    _box_part(f"{side}_body", mirror(FLAT_BODY)),
                    _box_part(f"{side}_tip", mirror(FLAT_TIP), "pad"),
                ],
            )
        )
    isf = [
        _gripper_tag(FLAT_PAD_HEIGHT),
        '<isf:contact name="left_pad" link="left_finger" geometry="left_tip" normal="0 -1 0" '
        'max_angle="0.3" points="256"/>',
        '<isf:contact name="right_pad" link="right_finger" geometry="right_tip" normal="0 1 0" '
        'max_angle="0.3" points="256"/>',
        f'<isf:initial joint="left_finger_joint" value="{_num(FLAT_Q_INITIAL)}"/>',
        '<isf:closing joint="left_finger_joint" sign="-1"/>',
    ]
    urdf = _robot_xml(
        "flat-parallel",
        "Parallel jaw with flat 2 x 2 cm pads.",
        links,
        _parallel_joints(FLAT_Q_LIMITS),
        isf,
    )
    return GripperFiles("flat-parallel", urdf, {})


def three_finger() -> GripperFiles:
    """A three-finger hand, two flexion joints per finger, convex fingertip pads."""
    capsule = trimesh.creation.capsule(
        height=HAND_PROXIMAL_LENGTH, radius=HAND_PROXIMAL_RADIUS, count=[12, 12]
    )
    # hemisphere centres at the proximal joint (z = 0) and at the distal joint
    capsule.apply_translation([0.0, 0.0, -capsule.bounds[0, 2] - HAND_PROXIMAL_RADIUS])
    meshes = {
        "proximal.stl": capsule,
        "distal.stl": _box_mesh(HAND_DISTAL_BOX),
        "pad.stl": _hand_pad_sheet(),
    }
    palm_origin = _origin((0, 0, -HAND_PALM_THICKNESS / 2))
    palm_geom = (
        f'<cylinder radius="{_num(HAND_PALM_RADIUS)}" length="{_num(HAND_PALM_THICKNESS)}"/>'
    )
    links = [Link("palm", [Part("palm_body", palm_geom, palm_origin, material="dark")])]
    joints, isf = [], [_gripper_tag(HAND_TCP_HEIGHT)]
    for k, angle_deg in enumerate(HAND_FINGER_ANGLES_DEG):
        theta = math.radians(angle_deg)
        f = f"f{k}"
        links.append(Link(f"{f}_proximal", [Part(f"{f}_proximal_body", _mesh("proximal.stl"))]))
        links.append(
            Link(
                f"{f}_distal",
                [
                    Part(f"{f}_distal_body", _mesh("distal.stl")),
                    Part(f"{f}_pad", _mesh("pad.stl"), material="pad"),
                ],
            )
        )
        base = (
            HAND_BASE_RADIUS * math.cos(theta),
            HAND_BASE_RADIUS * math.sin(theta),
            HAND_BASE_HEIGHT,
        )
        # flexion about -y of the finger frame (x radial outward): positive q closes inwards
        joints.append(Joint(f"{f}_proximal_joint", "revolute", "palm", f"{f}_proximal",
                            base, (0, 0, theta), axis=(0, -1, 0),
                            limits=HAND_PROXIMAL_LIMITS))  # fmt: skip
        joints.append(Joint(f"{f}_distal_joint", "revolute", f"{f}_proximal", f"{f}_distal",
                            (0, 0, HAND_PROXIMAL_LENGTH), (0, 0, 0), axis=(0, -1, 0),
                            limits=HAND_DISTAL_LIMITS))  # fmt: skip
        isf.append(
            f'<isf:contact name="{f}_pad" link="{f}_distal" geometry="{f}_pad" points="128"/>'
        )
    for k in range(len(HAND_FINGER_ANGLES_DEG)):
        isf.append(f'<isf:initial joint="f{k}_proximal_joint" value="{_num(HAND_INITIAL[0])}"/>')
        isf.append(f'<isf:initial joint="f{k}_distal_joint" value="{_num(HAND_INITIAL[1])}"/>')
    for k in range(len(HAND_FINGER_ANGLES_DEG)):  # flexion closes every finger
        isf.append(f'<isf:closing joint="f{k}_proximal_joint" sign="1"/>')
        isf.append(f'<isf:closing joint="f{k}_distal_joint" sign="1"/>')
    urdf = _robot_xml(
        "three-finger", "Three-finger hand, 2 flexion joints per finger.", links, joints, isf
    )
    return GripperFiles("three-finger", urdf, meshes)


BUILDERS = (paper_parallel, flat_parallel, three_finger)


# -------------------------------------------------------------------- write
def write(files: GripperFiles, out: Path) -> Path:
    """Write one gripper's URDF and meshes below ``out/<name>/``; returns the URDF path."""
    folder = out / files.name
    mesh_dir = folder / "meshes"
    if files.meshes:
        mesh_dir.mkdir(parents=True, exist_ok=True)
    folder.mkdir(parents=True, exist_ok=True)
    if mesh_dir.is_dir():
        for stale in sorted(mesh_dir.glob("*.stl")):
            if stale.name not in files.meshes:
                stale.unlink()
    for filename, mesh in sorted(files.meshes.items()):
        (mesh_dir / filename).write_bytes(trimesh.exchange.stl.export_stl(mesh))
    urdf_path = folder / f"{files.name}.urdf"
    urdf_path.write_text(files.urdf, encoding="utf-8")
    return urdf_path


# -------------------------------------------------------------- self-checks
def _check(condition: bool, message: str) -> None:
    if not condition:
        raise SystemExit(f"self-check failed: {message}")


def _contact_tags(urdf_path: Path) -> list[dict]:
    root = ET.parse(urdf_path).getroot()
    return [e.attrib for e in root.findall(f"{{{ISF_NS}}}contact")]


def _link_meshes(urdf_path: Path) -> dict[str, trimesh.Trimesh]:
    """Collision meshes by <collision name>, read back from the written STL files (float32)."""
    root = ET.parse(urdf_path).getroot()
    meshes = {}
    for collision in root.iter("collision"):
        mesh = collision.find("geometry/mesh")
        if mesh is not None:
            meshes[collision.get("name")] = trimesh.load(
                urdf_path.parent / mesh.get("filename"), force="mesh"
            )
    return meshes


def _frame_pose(model, data, link: str) -> np.ndarray:
    return data.oMf[model.getFrameId(link)].homogeneous.copy()


def self_check(urdf_path: Path) -> None:
    """Load ``urdf_path`` in Pinocchio (mimic=True) and check geometry; prints a summary line."""
    import pinocchio as pin

    model = pin.buildModelFromUrdf(str(urdf_path), mimic=True)
    _, cmodel = pin.buildModelsFromUrdf(
        str(urdf_path),
        package_dirs=[str(urdf_path.parent)],
        mimic=True,
        geometry_types=pin.GeometryType.COLLISION,
    )
    tags = _contact_tags(urdf_path)
    print(
        f"{urdf_path.relative_to(urdf_path.parents[2])}: nq={model.nq}, "
        f"collision objects={cmodel.ngeoms}, contacts={[t['name'] for t in tags]}"
    )
    root = ET.parse(urdf_path).getroot()
    for link in root.findall("link"):
        _check(link.find("collision") is not None, f"link {link.get('name')} has no <collision>")
    meshes = _link_meshes(urdf_path)
    for name, mesh in meshes.items():
        if not name.endswith("_pad"):
            _check(mesh.is_volume, f"{name} must be a closed mesh with outward normals")
    data = model.createData()
    name = urdf_path.stem
    if name == "paper-parallel":
        _check(model.nq == 1, "paper-parallel must have one actuated joint")
        q = np.array([PAPER_GROOVE_RADIUS])  # d = 0.016: both grooves lie on the test cylinder
        pin.framesForwardKinematics(model, data, q)
        for side in ("left", "right"):
            T = _frame_pose(model, data, f"{side}_finger")
            sheet = meshes[f"{side}_pad"]
            v = sheet.vertices @ T[:3, :3].T + T[:3, 3]
            dist = np.hypot(v[:, 1], v[:, 2] - PAPER_TIP_HEIGHT)
            _check(
                np.abs(dist - PAPER_GROOVE_RADIUS).max() < 1e-8,
                f"{side} groove not on the cylinder",
            )
            n = sheet.face_normals @ T[:3, :3].T
            c = sheet.triangles_center @ T[:3, :3].T + T[:3, 3]
            radial = c[:, 1:] - [0.0, PAPER_TIP_HEIGHT]
            _check(
                np.all(np.einsum("ij,ij->i", n[:, 1:], radial) < 0),
                f"{side} groove normals not inward",
            )
            ang = np.arctan2(np.abs(v[:, 2] - PAPER_TIP_HEIGHT), np.abs(v[:, 1]))
            _check(
                abs(ang.max() - PAPER_GROOVE_HALF_ARC) < 1e-6, f"{side} groove arc is not +-55 deg"
            )
            print(
                f"  {side} groove at q={q[0]}: max |distance to axis - R| = "
                f"{np.abs(dist - PAPER_GROOVE_RADIUS).max():.2e} m"
            )
    elif name == "flat-parallel":
        _check(model.nq == 1, "flat-parallel must have one actuated joint")
        pin.framesForwardKinematics(model, data, np.array([0.03]))
        for side, sign in (("left", 1.0), ("right", -1.0)):
            _check(
                abs(_frame_pose(model, data, f"{side}_finger")[1, 3] - sign * 0.03) < 1e-12,
                f"{side} finger does not follow q",
            )
    elif name == "three-finger":
        _check(model.nq == 6, "three-finger must have six actuated joints")
        q0 = np.tile(HAND_INITIAL, 3)
        pin.framesForwardKinematics(model, data, q0)
        pad = meshes["f0_pad"]
        centres = []
        for k in range(3):
            T = _frame_pose(model, data, f"f{k}_distal")
            c = pad.triangles_center @ T[:3, :3].T + T[:3, 3]
            n = pad.face_normals @ T[:3, :3].T
            towards_axis = -c[:, :2] / np.linalg.norm(c[:, :2], axis=1, keepdims=True)
            _check(
                np.all(np.einsum("ij,ij->i", n[:, :2], towards_axis) > 0.9),
                f"f{k} pad does not face the axis",
            )
            print(
                f"  f{k} pad centre at q0: radius {np.linalg.norm(c[:, :2], axis=1).mean():.4f} m, "
                f"z {c[:, 2].mean():.4f} m"
            )
            centres.append(c.mean(axis=0))
        _check(np.linalg.norm(np.mean(centres, axis=0) - [0, 0, HAND_TCP_HEIGHT]) < 1e-3,
               "the tool-centre point is not within 1 mm of the pads' centre at q0")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out",
        type=Path,
        default=REPO_ROOT / "grippers",
        help="output folder (default: grippers/)",
    )
    parser.add_argument("--no-check", action="store_true", help="skip the Pinocchio self-check")
    args = parser.parse_args(argv)
    for build in BUILDERS:
        path = write(build(), args.out)
        if not args.no_check:
            self_check(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
