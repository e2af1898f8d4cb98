"""What the tags of a tagged copy select: :class:`SurfacePreview` per contact, :class:`TagPreview`
for the copy (text summary and export of the selected faces)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import trimesh

from ..exceptions import (
    GeometryLoadError,
    MeshNotFoundError,
    ModelBuildError,
    OutputFileError,
    SurfaceSelectionError,
)
from ..gripper.loading import GripperReport, format_report, inspect_gripper, load_gripper
from ..gripper.mesh_paths import PackageDirs
from ..gripper.surface_sampling import load_geometry, select_faces, tag_elements
from ..gripper.urdf_tags import ContactTag, TaggedURDF, parse_tagged_urdf
from ..output_files import check_output_path, write_atomically
from ._urdf_source import Posed, face_normals, pose_urdf, read_urdf

__all__ = ["EXPORT_FORMATS", "SurfacePreview", "TagPreview", "check_export_path", "preview_surface",
           "preview_surfaces", "preview_tagged"]

EXPORT_FORMATS = ("glb", "obj", "ply")
"""File suffixes :meth:`TagPreview.export` writes (formats that keep face colours)."""


def check_export_path(path: str | Path) -> Path:
    """``path`` as a :class:`Path` once :meth:`TagPreview.export` can write it.

    Raises:
        OutputFileError: the suffix is not one of ``EXPORT_FORMATS``, or the path cannot
            become a regular file (:func:`isf.output_files.check_output_path`).
    """
    path = check_output_path(path, "export file")
    if path.suffix.lower().lstrip(".") not in EXPORT_FORMATS:
        raise OutputFileError(f"export file {path} has suffix {path.suffix!r}: name a "
                              f"{', '.join('.' + f for f in EXPORT_FORMATS)} file", path=path)
    return path


@dataclass(frozen=True, eq=False)
class SurfacePreview:
    """What one contact tag selected in the written copy.

    Attributes:
        name, link, source: from the tag.
        elements: names of the geometry elements the tag reads.
        n_faces: faces selected; 0 when the selection failed.
        n_faces_total: faces of those elements before the normal/box filters.
        area: area of the selected faces, m^2.
        centroid: area-weighted centroid of the selected faces, link frame, (3,), metres, or None.
        normal: unit area-weighted mean normal of the selected faces, link frame, (3,), or None.
        spread: largest angle between a selected face normal and ``normal``, radians.
        centroid_gripper, normal_gripper: the same at the initial configuration, gripper
            (root link) frame, or None when the kinematic model could not be built.
        triangles: the selected faces, link frame, shape (F, 3, 3), metres.
        problems: problems of this surface (selection and validation).
    """

    name: str
    link: str
    source: str
    elements: tuple[str, ...] = ()
    n_faces: int = 0
    n_faces_total: int = 0
    area: float = 0.0
    centroid: np.ndarray | None = None
    normal: np.ndarray | None = None
    spread: float = 0.0
    centroid_gripper: np.ndarray | None = None
    normal_gripper: np.ndarray | None = None
    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)), repr=False)
    problems: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class TagPreview:
    """Result of :func:`tag_urdf`: the copy, what each tag selected, and the validation.

    Attributes:
        source_path: the URDF that was read (unchanged).
        urdf_path: the tagged copy that was written.
        surfaces: one :class:`SurfacePreview` per contact, in tag order.
        report: :func:`isf.inspect_gripper` of the copy.
        rewritten_meshes: ``{filename as written in the source: absolute path written}``.
        namespace_added: False when the source already declared ``xmlns:isf``.
        q_initial: initial joint values by name, metres or radians (empty if no model).
        tag_time: wall time of writing the copy, seconds.
        validation_time: wall time of the validation and the preview, seconds.
    """

    source_path: Path
    urdf_path: Path
    surfaces: tuple[SurfacePreview, ...]
    report: GripperReport
    rewritten_meshes: dict[str, str]
    namespace_added: bool
    q_initial: dict[str, float]
    tag_time: float
    validation_time: float

    @property
    def problems(self) -> list[str]:
        """Every problem of the copy (those of :attr:`report` and of the surface previews)."""
        out = list(self.report.problems)
        for s in self.surfaces:
            out += [p for p in s.problems if p not in out]
        return out

    @property
    def ok(self) -> bool:
        """True when the copy loads with :func:`isf.load_gripper`."""
        return not self.problems

    def format(self) -> str:
        """A text summary: where the copy went, what every tag selected, and the validation."""
        lines = [f"tagged    {self.urdf_path}", f"from      {self.source_path} (unchanged)"]
        if self.rewritten_meshes:
            lines.append(
                f"meshes    {len(self.rewritten_meshes)} path(s) made absolute so the copy "
                "finds them:"
            )
            lines += [f"  {old} -> {new}" for old, new in self.rewritten_meshes.items()]
        if self.q_initial:
            q = ", ".join(f"{k}={v:.4g}" for k, v in self.q_initial.items())
            lines.append(f"q initial {q}")
        lines.append(f"surfaces  {len(self.surfaces)}")
        for s in self.surfaces:
            lines.append(
                f"  {s.name}: link {s.link!r}, {s.source} {', '.join(s.elements) or '-'}: "
                f"{s.n_faces}/{s.n_faces_total} faces, {1e4 * s.area:.3g} cm^2"
            )
            if s.centroid is not None:
                lines.append(
                    f"    link frame     centroid {_mm(s.centroid)} mm  normal {_dir(s.normal)}"
                    f"  spread {math.degrees(s.spread):.0f} deg"
                )
            if s.centroid_gripper is not None:
                lines.append(
                    f"    gripper frame  centroid {_mm(s.centroid_gripper)} mm  "
                    f"normal {_dir(s.normal_gripper)}  (at q initial)"
                )
            lines += [f"    problem: {p}" for p in s.problems]
        lines.append(
            f"timing    tag {1e3 * self.tag_time:.0f} ms, "
            f"validate {1e3 * self.validation_time:.0f} ms"
        )
        lines.append("validation (isf inspect):")
        lines += ["  " + ln for ln in format_report(self.report).splitlines()]
        return "\n".join(lines)

    def export(self, path: str | Path) -> Path:
        """Write the gripper at its initial configuration with the selected faces in red.

        Args:
            path: output file; any format trimesh writes with face colours (``.ply``,
                ``.glb``, ``.obj``); geometry in metres, gripper frame.

        Returns:
            the path written.

        Raises:
            GripperDescriptionError: the copy does not load (see :attr:`problems`).
            OutputFileError: as :func:`isf.registration.check_export_path` (checked before any
                work), or the write failed.
        """
        out = check_export_path(path)
        gripper = load_gripper(self.urdf_path)
        poses = gripper.link_poses(gripper.q_initial)
        parts = []
        for g in gripper.geometries:
            T = poses[g.link]
            mesh = trimesh.Trimesh(g.vertices @ T[:3, :3].T + T[:3, 3], g.faces, process=False)
            mesh.visual.face_colors = (170, 170, 170, 255)
            parts.append(mesh)
        for s in self.surfaces:
            if len(s.triangles) == 0:
                continue
            T = poses[s.link]
            tris = s.triangles @ T[:3, :3].T + T[:3, 3]
            # lift the patch 0.2 mm off the body so viewers draw it on top
            lift = 2e-4 * np.repeat(face_normals(tris)[:, None, :], 3, axis=1)
            patch = trimesh.Trimesh(
                (tris + lift).reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3), process=False
            )
            patch.visual.face_colors = (220, 30, 30, 255)
            parts.append(patch)
        data = trimesh.util.concatenate(parts).export(file_type=out.suffix.lower().lstrip("."))
        return write_atomically(out, data if isinstance(data, bytes) else data.encode("utf-8"),
                                "export file")


def _mm(v: np.ndarray) -> str:
    return "(" + " ".join(f"{1e3 * x:7.2f}" for x in v) + ")"


def _dir(v: np.ndarray | None) -> str:
    return "-" if v is None else "(" + " ".join(f"{x:+.3f}" for x in v) + ")"


def preview_tagged(urdf_path: str | Path, *, package_dirs: PackageDirs | None = None,
                   report: GripperReport | None = None) -> TagPreview:
    """What the tags of an existing tagged URDF select, as :func:`isf.registration.tag_urdf`
    describes the copy it writes (``isf inspect --export``); nothing is written.

    Args:
        urdf_path: the tagged URDF.
        package_dirs: optional ``{package: folder}`` map for ``package://`` mesh paths.
        report: its :func:`isf.inspect_gripper` report when already made.

    Raises:
        RegistrationError: the file is not readable UTF-8 text.
    """
    t0 = time.perf_counter()
    path, text = read_urdf(urdf_path)
    report = inspect_gripper(path, package_dirs=package_dirs) if report is None else report
    surfaces, q_initial = preview_surfaces(text, path.parent, report, package_dirs)
    return TagPreview(source_path=path, urdf_path=path, surfaces=surfaces, report=report,
                      rewritten_meshes={}, namespace_added=False,
                      q_initial=q_initial, tag_time=0.0,
                      validation_time=time.perf_counter() - t0)


def preview_surfaces(text: str, urdf_dir: Path, report: GripperReport,
                     package_dirs: PackageDirs | None = None
                     ) -> tuple[tuple[SurfacePreview, ...], dict[str, float]]:
    """What every ``<isf:contact>`` of the tagged URDF ``text`` selects
    (:func:`preview_surface`), and the initial joint values it is posed at ({} when the URDF
    does not build: ``report`` says why).

    Args:
        text: the tagged URDF's text.
        urdf_dir: its folder, for relative mesh paths.
        report: its :func:`isf.inspect_gripper` report; problems found here are added to it.
        package_dirs: optional ``{package: folder}`` map for ``package://`` mesh paths.
    """
    doc = parse_tagged_urdf(text)
    try:
        posed = pose_urdf(text, doc, ())
    except ModelBuildError:
        posed = None  # the report says why
    cache: dict = {}
    surfaces = tuple(preview_surface(tag, doc, urdf_dir, posed, report.problems, cache,
                                     package_dirs) for tag in doc.contacts)
    return surfaces, ({} if posed is None else posed.joint_values())


def preview_surface(
    tag: ContactTag,
    doc: TaggedURDF,
    urdf_dir: Path,
    posed: Posed | None,
    report_problems: list[str],
    cache: dict,
    package_dirs: PackageDirs | None = None,
) -> SurfacePreview:
    """What one contact tag selects in the tagged copy.

    Args:
        tag: the contact tag as read from the copy.
        doc: the copy, parsed.
        urdf_dir: the copy's folder, for relative mesh paths.
        posed: the copy's model at its initial configuration, or None when it does not build.
        report_problems: the validation's problems; those naming this contact are kept.
        cache: ``{file: (vertices, faces)}`` shared between the contacts.
        package_dirs: optional ``{package: folder}`` map for ``package://`` mesh paths.
    """
    problems = [p for p in report_problems if p.startswith(f"contact {tag.name!r}")]
    base = SurfacePreview(tag.name, tag.link, tag.source, problems=tuple(problems))
    link = doc.links.get(tag.link)
    if link is None:
        return base  # the report names the missing link
    try:
        elements = tag_elements(tag, link)
        meshes = [load_geometry(e, urdf_dir, package_dirs, cache) for e in elements]
        selection = select_faces(tag, meshes)
    except (SurfaceSelectionError, GeometryLoadError, MeshNotFoundError) as exc:
        if str(exc) not in problems:
            problems.append(str(exc))
        return replace(base, problems=tuple(problems))
    w = selection.areas / selection.areas.sum()
    centroid = w @ selection.triangles.mean(axis=1)
    mean = w @ selection.normals
    normal = mean / max(float(np.linalg.norm(mean)), 1e-300)
    spread = float(np.arccos(np.clip(selection.normals @ normal, -1.0, 1.0)).max())
    c_g = n_g = None
    if posed is not None and tag.link in posed.poses:
        T = posed.poses[tag.link]
        c_g, n_g = T[:3, :3] @ centroid + T[:3, 3], T[:3, :3] @ normal
    return replace(
        base,
        elements=tuple(e.name for e in elements),
        n_faces=len(selection.areas),
        n_faces_total=sum(len(m.faces) for m in meshes),
        area=selection.area,
        centroid=centroid,
        normal=normal,
        spread=spread,
        centroid_gripper=c_g,
        normal_gripper=n_g,
        triangles=selection.triangles,
    )
