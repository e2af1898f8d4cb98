"""Load a tagged URDF into a :class:`~isf.gripper.model.Gripper`, or report what is wrong with it.

:func:`inspect_gripper` and :func:`load_gripper` share one code path: every
check runs, every problem is collected, and only then does ``load_gripper``
raise :class:`~isf.exceptions.GripperDescriptionError` listing all of them.

Decisions:
    * Kinematics come from ``pin.buildModelFromXML(text, mimic=True)`` with a fixed
      base at the URDF root link, so ``q`` holds actuated joints only (see
      :mod:`isf.gripper.urdf_model` for mimic joints that Pinocchio visits before their leader).
    * ``Gripper.geometries`` holds every link's ``<collision>`` elements; a link
      without any collision falls back to its ``<visual>`` elements (vendor files
      sometimes describe a part only visually, and a collision check that ignores
      it would let fingers pass through it).
    * Visual meshes are read only when used (a contact tag with ``source="visual"``
      or the fallback above); a missing unused visual mesh is listed in the report
      but is not a problem.
    * Continuous, floating and planar joints are rejected: isf needs ``nq == nv``
      and finite limits for every actuated joint.
"""

from __future__ import annotations

import logging
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..exceptions import ConfigError, GripperDescriptionError
from .bundled import bundled_grippers
from .mesh_paths import MeshNotFoundError, PackageDirs, mesh_path_candidates
from .model import ContactSurface, Gripper, LinkGeometry
from .surface_sampling import (
    GeometryLoadError,
    SurfaceSelectionError,
    load_geometry,
    orientation_problem,
    sample_faces,
    select_faces,
    tag_elements,
)
from .urdf_model import ModelBuildError, build_model
from .urdf_tags import MAX_POINTS, GeometryElement, TaggedURDF, URDFReadError, parse_tagged_urdf

__all__ = [
    "GripperReport",
    "JointReport",
    "MeshReport",
    "SurfaceReport",
    "format_report",
    "inspect_gripper",
    "load_gripper",
]

log = logging.getLogger(__name__)

_ACTUATED_TYPES = ("revolute", "prismatic")


# ------------------------------------------------------------------- report
@dataclass(frozen=True)
class JointReport:
    """One URDF joint; limits in metres or radians (None when absent)."""

    name: str
    type: str
    parent: str
    child: str
    lower: float | None
    upper: float | None
    mimic_leader: str | None = None
    mimic_multiplier: float | None = None
    mimic_offset: float | None = None
    initial: float | None = None

    @property
    def actuated(self) -> bool:
        """True for a revolute or prismatic joint that mimics no other joint."""
        return self.type in _ACTUATED_TYPES and self.mimic_leader is None


@dataclass(frozen=True)
class MeshReport:
    """One ``<mesh>`` element: where it was looked for and whether isf needs it."""

    link: str
    element: str
    source: str
    filename: str
    path: Path | None
    tried: tuple[Path, ...]
    used: bool

    @property
    def found(self) -> bool:
        """True when the file exists."""
        return self.path is not None


@dataclass(frozen=True)
class SurfaceReport:
    """One contact surface: sampled points and the area of its selected faces (m^2)."""

    name: str
    link: str
    n_points: int
    area: float


@dataclass
class GripperReport:
    """What :func:`inspect_gripper` found; building it never raises for a user mistake.

    Attributes:
        source: the name or path that was asked for.
        name: bundled name or URDF file stem.
        urdf_path: the resolved URDF file, or None if none was found.
        root_link: the URDF root link (the gripper frame), or None.
        links: link names in file order.
        joints: every joint in file order.
        meshes: every ``<mesh>`` element of the file.
        surfaces: the contact surfaces that could be sampled.
        palm_link: the link that approaches the object.
        approach: unit approach direction in the palm link frame, or None.
        tcp_link: the link of the declared tool-centre point, or None.
        T_link_tcp: the declared tool-centre point in ``tcp_link``'s frame, (4, 4), or None.
        problems: one message per problem; empty when the gripper loads.
        load_time: wall time of the check, seconds.
    """

    source: str
    name: str = ""
    urdf_path: Path | None = None
    root_link: str | None = None
    links: tuple[str, ...] = ()
    joints: tuple[JointReport, ...] = ()
    meshes: tuple[MeshReport, ...] = ()
    surfaces: tuple[SurfaceReport, ...] = ()
    palm_link: str | None = None
    approach: np.ndarray | None = None
    tcp_link: str | None = None
    T_link_tcp: np.ndarray | None = None
    problems: list[str] = field(default_factory=list)
    load_time: float = 0.0

    @property
    def ok(self) -> bool:
        """True when no problem was found."""
        return not self.problems


# ----------------------------------------------------------- source lookup
def _find_urdf(name_or_path: str | Path) -> tuple[Path | None, str, str | None]:
    """(urdf path, gripper name, problem) for a bundled name, a file or a folder."""
    bundled = bundled_grippers()
    if not isinstance(name_or_path, (str, os.PathLike)):
        return None, repr(name_or_path), (
            f"a gripper is a bundled name ({', '.join(bundled) or 'none installed'}) or a URDF "
            f"path, got {type(name_or_path).__name__}: pass one of them")
    if isinstance(name_or_path, str) and name_or_path in bundled:
        return bundled[name_or_path], name_or_path, None
    path = Path(name_or_path).expanduser()
    if path.is_dir():
        urdfs = sorted(path.glob("*.urdf"))
        named = path / f"{path.name}.urdf"
        path = named if named.is_file() else (urdfs[0] if len(urdfs) == 1 else path)
    if path.is_file():
        return path.resolve(), path.stem, None
    names = ", ".join(bundled) or "none installed"
    return (
        None,
        str(name_or_path),
        (
            f"{str(name_or_path)!r} is neither a URDF file nor a bundled gripper "
            f"(bundled: {names}): give the path of a .urdf file"
        ),
    )


# ---------------------------------------------------------------- checks
def _joint_reports(doc: TaggedURDF) -> tuple[JointReport, ...]:
    initial = {t.joint: t.value for t in doc.initial}
    out = []
    for j in doc.joints.values():
        mimic = j.mimic if j.type != "fixed" else None  # a fixed joint ignores <mimic>
        out.append(
            JointReport(
                j.name,
                j.type,
                j.parent,
                j.child,
                j.lower,
                j.upper,
                mimic_leader=mimic.joint if mimic else None,
                mimic_multiplier=mimic.multiplier if mimic else None,
                mimic_offset=mimic.offset if mimic else None,
                initial=initial.get(j.name),
            )
        )
    return tuple(out)


AXIS_TOLERANCE = 1e-3
"""Largest ``| |axis| - 1 |`` accepted of a moving joint's ``<axis xyz>``."""


def _axis_problems(doc: TaggedURDF) -> list[str]:
    """A moving joint's axis must be a unit vector: urdfdom keeps a zero axis (the joint then
    never moves, while its value is reported) and rescales other lengths silently."""
    problems = []
    for j in doc.joints.values():
        if j.type in ("fixed", "floating", "planar") or j.axis is None:
            continue  # no axis, or a non-finite one (already reported)
        norm = float(np.linalg.norm(j.axis))
        if not abs(norm - 1.0) <= AXIS_TOLERANCE:
            xyz = " ".join(f"{v:g}" for v in j.axis)
            fix = "give the direction it moves along" if norm == 0.0 else "normalise it"
            problems.append(f"joint {j.name!r} <axis xyz='{xyz}'> has length {norm:.6g}, not "
                            f"1: {fix} (a unit vector in the joint frame)")
    return problems


def _joint_problems(joints: tuple[JointReport, ...]) -> list[str]:
    problems = []
    by_name = {j.name: j for j in joints}
    for j in joints:
        if j.type == "continuous":
            problems.append(
                f"joint {j.name!r} is continuous, which isf does not support: make it "
                "revolute with finite <limit lower=... upper=...> in radians"
            )
        elif j.type not in (*_ACTUATED_TYPES, "fixed"):
            problems.append(
                f"joint {j.name!r} has type {j.type!r}; isf supports revolute, prismatic "
                "and fixed joints: change its type"
            )
        elif j.actuated:
            unit = "radians" if j.type == "revolute" else "metres"
            if j.lower is None or j.upper is None:
                problems.append(
                    f"actuated joint {j.name!r} lacks finite limits: add "
                    f"<limit lower=... upper=...> in {unit}"
                )
            elif not j.lower < j.upper:
                problems.append(
                    f"actuated joint {j.name!r} has lower={j.lower} >= upper={j.upper}: "
                    f"give a non-empty range in {unit}"
                )
        if j.mimic_leader is not None:
            leader = by_name.get(j.mimic_leader)
            if leader is None:
                problems.append(
                    f"joint {j.name!r} mimics {j.mimic_leader!r}, which does not exist: "
                    "fix <mimic joint>"
                )
            elif not leader.actuated:
                problems.append(
                    f"joint {j.name!r} mimics {leader.name!r}, which is not an actuated joint: "
                    "make it mimic the actuated leader directly"
                )
    return problems


def _tcp_problems(doc: TaggedURDF, tcp_link: str) -> list[str]:
    """``<isf:gripper tcp_link>`` must name a link rigidly attached to the root link (only
    fixed joints between them): a robot's tool-centre point does not move with the fingers."""
    where = f"<isf:gripper tcp_link={tcp_link!r}>"
    if tcp_link not in doc.links:
        return [f"{where} names a link that does not exist; links: {', '.join(doc.links)}"]
    parent_joint = {j.child: j for j in doc.joints.values()}
    link, seen = tcp_link, set()
    while link in parent_joint and link not in seen:
        seen.add(link)
        joint = parent_joint[link]
        if joint.type != "fixed":
            return [f"{where} moves with joint {joint.name!r}: name a link fixed to the root "
                    f"link (e.g. {doc.root_link!r}) and give the point in its frame"]
        link = joint.parent
    return []


def _initial_problems(doc: TaggedURDF, joints: tuple[JointReport, ...]) -> list[str]:
    problems = []
    by_name = {j.name: j for j in joints}
    actuated = ", ".join(j.name for j in joints if j.actuated) or "none"
    for tag in doc.initial:
        j = by_name.get(tag.joint)
        where = f"<isf:initial joint={tag.joint!r}>"
        if j is None:
            problems.append(
                f"{where} names a joint that does not exist; actuated joints: {actuated}"
            )
        elif j.mimic_leader is not None:
            problems.append(
                f"{where}: the joint mimics {j.mimic_leader!r}; give the initial value of "
                f"{j.mimic_leader!r} instead"
            )
        elif not j.actuated:
            problems.append(
                f"{where}: the joint is {j.type}, not actuated; actuated joints: {actuated}"
            )
        elif j.lower is not None and j.upper is not None and not j.lower <= tag.value <= j.upper:
            problems.append(
                f"{where} value={tag.value} lies outside the joint limits "
                f"[{j.lower}, {j.upper}]: choose a value inside them"
            )
    return problems


def _closing_problems(doc: TaggedURDF, joints: tuple[JointReport, ...]) -> list[str]:
    actuated = [j.name for j in joints if j.actuated and j.mimic_leader is None]
    return [f"<isf:closing joint={tag.joint!r}> names no actuated joint; actuated joints: "
            f"{', '.join(actuated) or 'none'}" for tag in doc.closing if tag.joint not in actuated]


# ---------------------------------------------------------------- meshes
def _used_elements(doc: TaggedURDF) -> list[GeometryElement]:
    """Elements isf reads: collisions (visuals for links without any) and tagged visuals."""
    used: dict[tuple[str, str, int], GeometryElement] = {}
    for link in doc.links.values():
        for e in link.collisions or link.visuals:
            used[(e.link, e.source, e.index)] = e
    for tag in doc.contacts:
        link = doc.links.get(tag.link)
        if link is not None and tag.source == "visual":
            for e in link.visuals:
                used[(e.link, e.source, e.index)] = e
    return list(used.values())


def _mesh_reports(doc: TaggedURDF, urdf_dir: Path, package_dirs, used) -> tuple[MeshReport, ...]:
    used_ids = {id(e) for e in used}
    out = []
    for link in doc.links.values():
        for e in (*link.collisions, *link.visuals):
            if e.shape != "mesh" or not e.filename:
                continue
            tried = tuple(mesh_path_candidates(e.filename, urdf_dir, package_dirs))
            path = next((p for p in tried if p.is_file()), None)
            out.append(
                MeshReport(e.link, e.name, e.source, e.filename, path, tried, id(e) in used_ids)
            )
    return tuple(out)


def _load_meshes(used, urdf_dir: Path, package_dirs, problems: list[str]) -> dict:
    """Trimesh of every usable element, keyed by ``id(element)``; failures go to ``problems``."""
    cache: dict = {}
    meshes = {}
    for e in used:
        if e.shape is None:
            continue  # already reported by the parser
        try:
            meshes[id(e)] = load_geometry(e, urdf_dir, package_dirs, cache)
        except (MeshNotFoundError, GeometryLoadError) as exc:
            problems.append(f"link {e.link!r} <{e.source}> {e.name!r}: {exc}")
    return meshes


def _center(meshes) -> np.ndarray | None:
    """Area-weighted centroid of the surfaces of ``meshes``, or None."""
    if not meshes:
        return None
    tris = np.concatenate([m.triangles for m in meshes])
    areas = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    if areas.sum() <= 0:
        return tris.reshape(-1, 3).mean(axis=0)
    return areas @ tris.mean(axis=1) / areas.sum()


# -------------------------------------------------------------- surfaces
def _surfaces(
    doc: TaggedURDF, meshes: dict, problems: list[str], points: int | None
) -> list[ContactSurface]:
    if not doc.contacts:
        problems.append(
            "the URDF has no <isf:contact> tag: tag at least one contact surface "
            "(see docs/gripper-tags.md)"
        )
    surfaces = []
    for tag in doc.contacts:
        link = doc.links.get(tag.link)
        if link is None:
            problems.append(
                f"contact {tag.name!r} names link {tag.link!r}, which does not exist; "
                f"links: {', '.join(doc.links)}"
            )
            continue
        try:
            elements = tag_elements(tag, link)
        except SurfaceSelectionError as exc:
            problems.append(str(exc))
            continue
        if any(id(e) not in meshes for e in elements):
            continue  # the missing or unreadable geometry is already reported
        tag_meshes = [meshes[id(e)] for e in elements]
        try:
            selection = select_faces(tag, tag_meshes)
        except SurfaceSelectionError as exc:
            problems.append(str(exc))
            continue
        link_meshes = [meshes[id(e)] for e in (link.collisions or link.visuals) if id(e) in meshes]
        center = _center(link_meshes)
        center = _center(tag_meshes) if center is None else center
        problem = orientation_problem(tag, tag_meshes, elements, selection, center)
        if problem:
            problems.append(problem)
        surfaces.append(sample_faces(tag.name, tag.link, selection, points or tag.points))
    return surfaces


# ----------------------------------------------------------------- model
def _build_model(text: str, doc: TaggedURDF, problems: list[str]) -> pin.Model | None:
    try:
        return build_model(text, doc)
    except ModelBuildError as exc:
        problems.append(str(exc))
        return None


def initial_configuration(model: pin.Model, doc: TaggedURDF) -> np.ndarray:
    """The initial joint vector: ``<isf:initial>`` values, else the middle of each joint's
    limits."""
    values = {t.joint: t.value for t in doc.initial}
    q = 0.5 * (np.asarray(model.lowerPositionLimit) + np.asarray(model.upperPositionLimit))
    for jid in range(1, model.njoints):
        joint = model.joints[jid]
        if joint.nq > 0 and model.names[jid] in values:
            q[joint.idx_q] = values[model.names[jid]]
    return q


# ------------------------------------------------------------------- core
def _load(
    name_or_path: str | Path, package_dirs: PackageDirs | None, points: int | None = None
) -> tuple[GripperReport, Gripper | None]:
    start = time.perf_counter()
    report = GripperReport(source=str(name_or_path))
    path, report.name, problem = _find_urdf(name_or_path)
    report.urdf_path = path
    if problem is None:
        try:
            text = path.read_text(encoding="utf-8")
            doc = parse_tagged_urdf(text)
        except (OSError, UnicodeDecodeError) as exc:
            problem = f"cannot read {path} ({exc}): check the file"
        except URDFReadError as exc:
            problem = f"{path}: {exc}"
    if problem is not None:
        report.problems.append(problem)
        report.load_time = time.perf_counter() - start
        return report, None

    problems = report.problems
    problems += doc.problems
    report.root_link = doc.root_link
    report.links = tuple(doc.links)
    report.joints = _joint_reports(doc)
    joint_problems = _joint_problems(report.joints) + _axis_problems(doc)
    problems += joint_problems
    problems += _initial_problems(doc, report.joints)
    problems += _closing_problems(doc, report.joints)
    tag = doc.gripper
    report.palm_link = (tag.palm_link if tag else None) or doc.root_link
    report.approach = tag.approach if tag else None
    if tag and tag.tcp_link:
        problems += _tcp_problems(doc, tag.tcp_link)
        report.tcp_link, report.T_link_tcp = tag.tcp_link, tag.T_link_tcp
    if tag and tag.palm_link and tag.palm_link not in doc.links:
        problems.append(
            f"<isf:gripper palm_link={tag.palm_link!r}> names a link that does not exist; "
            f"links: {', '.join(doc.links)}"
        )

    urdf_dir = path.parent
    used = _used_elements(doc)
    report.meshes = _mesh_reports(doc, urdf_dir, package_dirs, used)
    meshes = _load_meshes(used, urdf_dir, package_dirs, problems)
    surfaces = _surfaces(doc, meshes, problems, points)
    report.surfaces = tuple(SurfaceReport(s.name, s.link, len(s.points), s.area) for s in surfaces)
    # a broken joint tree is already reported; Pinocchio would only repeat it less clearly
    model = None if joint_problems or doc.root_link is None else _build_model(text, doc, problems)

    gripper = None
    if not problems and model is not None:
        geometries = tuple(
            LinkGeometry(e.link, e.name, np.asarray(m.vertices), np.asarray(m.faces))
            for link in doc.links.values()
            for e in link.collisions or link.visuals
            if (m := meshes.get(id(e))) is not None
        )
        gripper = Gripper(
            name=report.name,
            model=model,
            surfaces=tuple(surfaces),
            q_initial=initial_configuration(model, doc),
            geometries=geometries,
            urdf_path=path,
            palm_link=report.palm_link,
            approach=report.approach,
            tcp_link=tag.tcp_link if tag else None,
            T_link_tcp=tag.T_link_tcp if tag else None,
            mimic={j.name: j.mimic for j in doc.joints.values()
                   if j.mimic is not None and j.type in _ACTUATED_TYPES},
            closing={t.joint: t.sign for t in doc.closing},
        )
    report.load_time = time.perf_counter() - start
    log.debug("checked %s in %.1f ms: %d problems", path, 1e3 * report.load_time, len(problems))
    return report, gripper


def inspect_gripper(
    name_or_path: str | Path, *, package_dirs: PackageDirs | None = None
) -> GripperReport:
    """Check a tagged URDF and describe it; never raises for a mistake in the file.

    Args:
        name_or_path: a bundled gripper name, a URDF file, or a folder holding one.
        package_dirs: optional ``{package: folder}`` map for ``package://`` mesh paths.

    Returns:
        the :class:`GripperReport`; ``report.problems`` lists everything wrong.
    """
    return _load(name_or_path, package_dirs)[0]


def load_gripper(
    name_or_path: str | Path,
    *,
    package_dirs: PackageDirs | None = None,
    points_per_surface: int | None = None,
) -> Gripper:
    """Load a tagged URDF as a :class:`~isf.gripper.model.Gripper`.

    Args:
        name_or_path: a bundled gripper name, a URDF file, or a folder holding one.
        package_dirs: optional ``{package: folder}`` map for ``package://`` mesh paths.
        points_per_surface: sample every contact surface with this many points instead of
            its tag's ``points`` (more: finer fits, slower; fewer: faster).

    Raises:
        GripperDescriptionError: listing every problem found (see :func:`inspect_gripper`).
        ConfigError: ``points_per_surface`` is not an integer in [1, MAX_POINTS].
    """
    if points_per_surface is not None and not (
        isinstance(points_per_surface, int) and 1 <= points_per_surface <= MAX_POINTS
    ):
        raise ConfigError(
            f"points_per_surface must be an integer in [1, {MAX_POINTS}], "
            f"got {points_per_surface!r}"
        )
    report, gripper = _load(name_or_path, package_dirs, points_per_surface)
    if gripper is None:
        raise GripperDescriptionError(report.source, report.problems)
    return gripper


# ----------------------------------------------------------------- output
def _num(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.4g}"


def format_report(report: GripperReport) -> str:
    """The report as the text ``isf inspect`` prints."""
    lines = [f"gripper   {report.name}", f"file      {report.urdf_path or '-'}"]
    if report.root_link is not None or report.links:
        approach = "-" if report.approach is None else " ".join(f"{v:.3g}" for v in report.approach)
        lines += [
            f"root link {report.root_link or '-'}   palm link {report.palm_link or '-'}   "
            f"approach {approach}",
            f"links     {len(report.links)}: {', '.join(report.links)}",
        ]
        if report.tcp_link is not None:
            xyz = " ".join(f"{v:.4g}" for v in report.T_link_tcp[:3, 3])
            lines.append(f"tcp       {xyz} m in {report.tcp_link}")
    if report.joints:
        n_act = sum(j.actuated for j in report.joints)
        n_mimic = sum(j.mimic_leader is not None for j in report.joints)
        lines.append(f"joints    {len(report.joints)} ({n_act} actuated, {n_mimic} mimic)")
        lines.append(f"  {'name':<28} {'type':<10} {'lower':>9} {'upper':>9} {'initial':>9}  mimic")
        for j in report.joints:
            if j.type == "fixed":
                continue
            mimic = (
                ""
                if j.mimic_leader is None
                else (f"{_num(j.mimic_multiplier)} * {j.mimic_leader} + {_num(j.mimic_offset)}")
            )
            init = j.initial
            if init is None and j.actuated and j.lower is not None and j.upper is not None:
                init = 0.5 * (j.lower + j.upper)
            lines.append(
                f"  {j.name:<28} {j.type:<10} {_num(j.lower):>9} {_num(j.upper):>9} "
                f"{_num(init) if j.actuated else '':>9}  {mimic}"
            )
    if report.meshes:
        missing = [m for m in report.meshes if not m.found]
        lines.append(f"meshes    {len(report.meshes) - len(missing)} found, {len(missing)} missing")
        for m in missing:
            note = "" if m.used else " (unused)"
            lines.append(f"  missing{note}: {m.link}/{m.element}: {m.filename}")
    if report.surfaces:
        lines.append(f"surfaces  {len(report.surfaces)}")
        lines.append(f"  {'name':<20} {'link':<28} {'points':>6} {'area [cm^2]':>12}")
        for s in report.surfaces:
            lines.append(f"  {s.name:<20} {s.link:<28} {s.n_points:>6} {1e4 * s.area:>12.3f}")
    if report.problems:
        lines.append(f"problems  {len(report.problems)}")
        lines += [f"  - {p}" for p in report.problems]
    else:
        lines.append(f"OK (checked in {1e3 * report.load_time:.0f} ms)")
    return "\n".join(lines)
