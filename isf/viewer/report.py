"""``isf show``: a plan file as one self-contained HTML page (plotly.js inlined, no network).

The page holds the object (its mesh, or its points; for a scene also the table and the unseen
space as a faint volume), the gripper's link meshes at the chosen grasp's pose and joints,
the gripper's contact points coloured by their signed distance to the object, the list of grasps
(choosing a row shows that grasp) and the chosen grasp's convergence plot (the paper's Fig. 5).

What the page carries: every array once (object, link meshes in their own frames, contact
points in their links' frames, as base64 float32/int32), and per grasp only poses (``T_object_part``
of every mesh part and ``T_object_link`` of every contact link, 3x4 row-major), the contact
points' distances and the ``convergence`` record of the plan file. The page's script
(``report.js``) places the parts when a grasp is chosen.
"""

from __future__ import annotations

import base64
import html
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..output_files import check_output_path, write_atomically
from .gripper_meshes import GripperMeshes
from .plan_file import PlanFile, PlanSources

__all__ = ["CONTACT_RANGE", "CONTENT_POLICY", "UNSEEN_GRID", "ReportSummary", "report_data",
           "report_html", "write_report"]

CONTACT_RANGE = 0.005
"""Signed distances of the contact points are coloured over [-CONTACT_RANGE, CONTACT_RANGE], metres."""

UNSEEN_GRID = 28
"""Grid cells per axis on which a scene's unseen space is sampled for its faint volume."""

_SCRIPT = Path(__file__).with_name("report.js")

CONTENT_POLICY = ("default-src 'none'; script-src 'unsafe-inline' 'unsafe-eval'; "
                  "style-src 'unsafe-inline'; img-src data: blob:; font-src data:")
"""The page's Content-Security-Policy: its inline scripts and styles, nothing fetched."""


@dataclass(frozen=True)
class ReportSummary:
    """What :func:`report_html` put into a page.

    Attributes:
        grasps: grasps shown.
        object_triangles, object_points: the object's triangles drawn, or its points (a cloud).
        gripper_triangles: triangles of the gripper's link meshes.
        contact_points: the gripper's contact points.
        size: bytes of the page.
    """

    grasps: int
    object_triangles: int
    object_points: int
    gripper_triangles: int
    contact_points: int
    size: int


def _b64(array: np.ndarray, dtype) -> str:
    """An array as base64 of its little-endian ``dtype`` bytes (read back by report.js)."""
    return base64.b64encode(np.ascontiguousarray(array, dtype=np.dtype(dtype).newbyteorder("<"))
                            .tobytes()).decode("ascii")


def _mesh(vertices: np.ndarray, faces: np.ndarray) -> dict:
    return {"vertices": _b64(vertices, np.float32), "faces": _b64(faces, np.int32)}


def _rows(T: np.ndarray) -> list[float]:
    """The top 3x4 of each (…, 4, 4) pose, row-major, flattened."""
    return [round(float(v), 7) for v in np.asarray(T)[..., :3, :].reshape(-1)]


def _number(x) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _joint_units(gripper) -> dict[str, str]:
    """``mm`` for each prismatic joint, ``deg`` for the others, by name."""
    model = gripper.model
    return {name: "mm" if model.joints[model.getJointId(name)].shortname().startswith("JointModelP")
            else "deg" for name in gripper.joint_names}


def _table(scene, surface_points: np.ndarray) -> dict | None:
    """A square of the table plane under the scene's points (twice their extent across)."""
    if scene.table is None:
        return None
    n, offset = scene.table.normal, scene.table.offset
    centre = surface_points.mean(axis=0)
    centre = centre - (n @ centre - offset) * n
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    half = float(np.ptp(surface_points, axis=0).max())
    corners = np.array([centre + half * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return _mesh(corners, np.array([[0, 1, 2], [0, 2, 3]]))


def _unseen(scene, surface_points: np.ndarray) -> dict:
    """The unseen space's depth on a grid around the scene's points (for an isosurface)."""
    lo, hi = surface_points.min(axis=0), surface_points.max(axis=0)
    pad = 0.25 * (hi - lo).max()
    axes = [np.linspace(a - pad, b + pad, UNSEEN_GRID) for a, b in zip(lo, hi)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    depth = scene.unseen.depth_inside(grid)
    if scene.table is not None:  # below the table is the table's, not the unseen space's
        depth[grid @ scene.table.normal < scene.table.offset] = 0.0
    return {"points": _b64(grid, np.float32), "depth": _b64(depth, np.float32),
            "max": float(depth.max())}


def _contact_distances(surface, points: np.ndarray) -> np.ndarray:
    """Signed distance of each point to its nearest object point, metres (< 0: behind that
    point's outward normal, inside)."""
    distance, index = surface.nearest(points)
    side = np.einsum("ij,ij->i", points - surface.points[index], surface.normals[index])
    return np.where(side < 0.0, -distance, distance)


def report_data(plan: PlanFile, sources: PlanSources, meshes: GripperMeshes,
                top: int | None = None) -> dict:
    """The page's data (see the module docstring): every array once, per grasp poses and figures.

    Args:
        plan: the plan file.
        sources: its gripper and object (:func:`isf.viewer.load_sources`).
        meshes: the gripper's link meshes.
        top: show only the best ``top`` grasps (default all).
    """
    gripper, surface, scene = sources.gripper, sources.surface, sources.scene
    grasps = plan.grasps if top is None else plan.grasps[:top]
    if surface.is_mesh:
        obj = {"kind": "mesh", **_mesh(surface.mesh_vertices, surface.mesh_faces)}
    else:
        obj = {"kind": "cloud", "points": _b64(surface.points, np.float32)}
    links = sorted({s.link for s in gripper.surfaces})
    contact_link = np.concatenate([np.full(len(s.points), links.index(s.link)) for s in gripper.surfaces])
    contact_local = np.concatenate([s.points for s in gripper.surfaces])
    rows = []
    for g in grasps:
        T_og = np.asarray(g["T_object_gripper"], dtype=float)
        joints = {k: float(v) for k, v in g["joints"].items()}
        q = np.array([joints.get(name, 0.0) for name in gripper.joint_names])
        poses = gripper.link_poses(q)
        T_links = np.stack([T_og @ poses[link] for link in links])
        world = np.einsum("pij,pj->pi", T_links[contact_link, :3, :3], contact_local) \
            + T_links[contact_link, :3, 3]
        error = g.get("error", {})
        rows.append({
            "rank": g["rank"], "valid": g.get("valid"), "collision_free": g["collision_free"],
            "status": g["status"], "iterations": g["iterations"], "repaired": g.get("repaired"),
            "centred": g.get("centred"),
            "mean_distance": error.get("mean_distance"),
            "clearance": g.get("clearance"), "penetration": g.get("penetration"),
            "colliding_links": g.get("colliding_links", []),
            "duplicate_of": g.get("duplicate_of"),
            "closing_obstructed_by": g.get("closing_obstructed_by") or [],
            "epsilon": (g.get("quality") or {}).get("epsilon"),
            "min_margin": (g.get("quality") or {}).get("min_margin"),
            "squeeze_imbalance": (g.get("quality") or {}).get("squeeze_imbalance"),
            "physics": _physics(g.get("validation")),
            "T_parts": _rows(T_og @ meshes.part_poses(joints)),
            "T_links": _rows(T_links),
            "distance": _b64(_contact_distances(surface, world), np.float32),
            "convergence": g.get("convergence"),
        })
    stats = plan.data.get("stats", {})
    return {
        "title": f"{plan.data['gripper']} on {plan.data['object']}",
        "subtitle": (f"{len(grasps)} of {len(plan.grasps)} grasps shown; "
                     f"{stats.get('valid', '?')} valid of {stats.get('samples', '?')} samples "
                     f"({plan.path.name})"),
        "object": obj,
        "table": None if scene is None else _table(scene, surface.points),
        "unseen": None if scene is None else _unseen(scene, surface.points),
        "parts": [{"name": p.name, **_mesh(p.vertices, p.faces)} for p in meshes.parts],
        "contacts": {"points": _b64(contact_local, np.float32),
                     "link": _b64(contact_link, np.int32), "range": CONTACT_RANGE},
        "joint_units": _joint_units(gripper),
        "grasps": rows,
    }


_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{policy}">
<title>{title}</title>
<style>
body {{ font: 13px system-ui, sans-serif; margin: 0; display: flex; height: 100vh; }}
#side {{ width: 44em; display: flex; flex-direction: column; border-right: 1px solid #ccc; }}
#list {{ overflow-y: auto; flex: 1; }}
#main {{ flex: 1; display: flex; flex-direction: column; min-width: 0; }}
#view {{ flex: 3; min-height: 300px; }}
#plot {{ flex: 2; min-height: 220px; border-top: 1px solid #ccc; }}
h1 {{ font-size: 15px; margin: 8px; }} p {{ margin: 0 8px 8px; color: #555; }}
table {{ border-collapse: collapse; width: 100%; }}
th, td {{ padding: 2px 6px; text-align: right; border-bottom: 1px solid #eee; }}
th {{ position: sticky; top: 0; background: #f4f4f4; }}
tr.grasp {{ cursor: pointer; }} tr.grasp:hover {{ background: #eef4ff; }}
tr.chosen {{ background: #cfe0ff !important; }}
td.no {{ color: #b00; }} td.yes {{ color: #070; }}
</style></head>
<body>
<div id="side"><h1>{title}</h1><p>{subtitle}</p><div id="list"></div></div>
<div id="main"><div id="view"></div><div id="plot"></div></div>
<script>{plotly}</script>
<script type="application/json" id="isf-data">{data}</script>
<script>{script}</script>
</body></html>
"""


def report_html(data: dict) -> str:
    """The page for :func:`report_data`'s ``data``: plotly.js, the data and report.js inlined."""
    from plotly.offline import get_plotlyjs

    text = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    return _PAGE.format(policy=CONTENT_POLICY, title=html.escape(data["title"]),
                        subtitle=html.escape(data["subtitle"]), plotly=get_plotlyjs(),
                        data=text, script=_SCRIPT.read_text(encoding="utf-8"))


def write_report(plan: PlanFile, sources: PlanSources, out: str | Path, *, top: int | None = None,
                 geometry: str = "collision") -> ReportSummary:
    """Write the page of ``plan`` to ``out`` (atomically, with the user's umask).

    Args:
        plan, sources: the plan file and its gripper and object.
        out: the HTML file to write.
        top: show only the best ``top`` grasps (default all).
        geometry: the gripper's ``collision`` or ``visual`` meshes.

    Raises:
        OutputFileError: ``out`` cannot be written (checked before any work).
        GripperDescriptionError: yourdfpy cannot read the gripper's URDF.
    """
    out = check_output_path(out, "report file")
    meshes = GripperMeshes(sources.gripper.urdf_path, geometry)
    data = report_data(plan, sources, meshes, top)
    page = report_html(data).encode("utf-8")
    write_atomically(out, page, "report file")
    surface = sources.surface
    return ReportSummary(
        grasps=len(data["grasps"]),
        object_triangles=len(surface.mesh_faces) if surface.is_mesh else 0,
        object_points=0 if surface.is_mesh else surface.n_points,
        gripper_triangles=sum(len(p.faces) for p in meshes.parts),
        contact_points=sum(len(s.points) for s in sources.gripper.surfaces),
        size=len(page))


def _physics(validation: dict | None) -> str | None:
    """The ``isf validate`` outcome of a grasp as the list shows it (e.g. ``held 6/6``), or None
    when the plan was not validated."""
    if not validation:
        return None
    return f"{validation['outcome']} {validation['held_directions']}/6"
