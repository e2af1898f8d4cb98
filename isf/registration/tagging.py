"""Register a stock gripper URDF: tag its contact surfaces in a copy and show the selection.

The shortest path from a vendor URDF (meshes untouched) to a gripper isf can plan with::

    from isf.registration.tagging import suggest_approach, suggest_contacts, tag_urdf

    preview = tag_urdf(src, "hand_isf.urdf", suggest_contacts(src), approach=suggest_approach(src))
    print(preview.format())

:func:`tag_urdf` writes a **copy** of the URDF text with ``xmlns:isf`` declared on ``<robot>``
and the ``isf:*`` elements (docs/gripper-tags.md) inserted just before ``</robot>``. The edit
is textual, so the copy is byte-identical to the vendor file apart from

* the namespace declaration (left alone when the file already binds ``isf`` correctly),
* the inserted ``isf:*`` lines,
* mesh filenames that would not resolve from the copy's folder.

Mesh paths (decision): the copy must load with **no package map**. Every ``<mesh filename>`` is
resolved from the original's folder (with ``package_dirs`` if given); if the same name does not
resolve to the same file from the copy's folder without a package map, it is replaced by the
file's absolute path. Writing the copy beside the original therefore changes no mesh path; a
copy elsewhere gets absolute paths for relative and ``package://`` names (it then depends on the
vendor folder staying where it is, which :func:`tag_urdf` records in
:attr:`TagPreview.rewritten_meshes`). Names that resolve nowhere are kept as written and show up
as problems of the validation.

Undeclared foreign prefixes (Robotiq's ``drake:``) are not touched: the copy is exactly as valid
for other tools as the vendor file was, and isf's reader declares such prefixes itself.

:func:`suggest_contacts` proposes one contact per fingertip: the leaf links of the kinematic tree
below a movable joint, each with the face normal that faces the other fingertips at the initial
configuration. Its heuristics are documented on the function; the result is a list of ordinary
:class:`ContactSpec` values to accept or edit.
"""

from __future__ import annotations

import logging
import math
import os
import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr, unescape

import numpy as np
import pinocchio as pin
import trimesh

from ..exceptions import ISFError
from ..gripper.loading import GripperReport, initial_configuration, format_report, inspect_gripper
from ..gripper.mesh_paths import MeshNotFoundError, PackageDirs, mesh_path_candidates, resolve_mesh_path
from ..gripper.surface_sampling import (
    GeometryLoadError,
    SurfaceSelectionError,
    load_geometry,
    select_faces,
    tag_elements,
)
from ..gripper.urdf_model import ModelBuildError, build_model
from ..gripper.urdf_tags import (
    ISF_NS,
    MAX_POINTS,
    ContactTag,
    InitialTag,
    TaggedURDF,
    URDFReadError,
    parse_tagged_urdf,
)

__all__ = [
    "ContactSpec",
    "RegistrationError",
    "SurfacePreview",
    "TagPreview",
    "suggest_approach",
    "suggest_contacts",
    "tag_urdf",
]

log = logging.getLogger(__name__)

_MOVABLE = ("revolute", "prismatic", "continuous")
_ATTR_FLOAT = "{:.6g}"  # micrometres for lengths up to 1 m, 1e-6 for unit vectors
# suggest_contacts: faces considered around the direction to the other fingertips, radians
_SEARCH_ANGLE = 0.8
# faces whose normals lie within this angle form one flat cluster, radians
_CLUSTER_ANGLE = 0.1
# a cluster holding at least this share of the considered area counts as a flat pad
_FLAT_SHARE = 0.5
# a leaf is dropped when another leaf has more movable joints and is this much farther away
_SIDE_LINK_RATIO = 0.75
_MAX_CLUSTER_SEEDS = 400
# cone half-angles of suggested contacts: a flat pad's faces only; a cap of a rounded tip
_PAD_ANGLE = 0.3
_TIP_ANGLE = 0.5
# a pad is cut along a link axis only if that axis is this close to the approach, radians
_DISTAL_AXIS_ANGLE = 0.35
_BOX_MARGIN = 0.01  # metres added around the link geometry on the box's free axes


class RegistrationError(ISFError, ValueError):
    """Bad input to :func:`tag_urdf` or :func:`suggest_contacts` (the message names the fix)."""


# ------------------------------------------------------------------ specs
def _vector(value, what: str, *, direction: bool = False) -> tuple[float, float, float] | None:
    """``value`` as 3 floats (None stays None); a ``direction`` must not be zero."""
    if value is None:
        return None
    try:
        v = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        v = np.array([])
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise RegistrationError(f"{what}={value!r} must be 3 finite numbers, e.g. (0, -1, 0)")
    if direction and float(np.linalg.norm(v)) < 1e-9:
        raise RegistrationError(f"{what}={value!r} is the zero vector: give a direction")
    return tuple(float(x) for x in v)


@dataclass(frozen=True)
class ContactSpec:
    """One ``<isf:contact>`` to write; fields mean what the tag's attributes mean.

    Attributes:
        name: unique surface name, e.g. ``"left_pad"``.
        link: the link that carries the surface.
        geometry: name of one ``<collision>``/``<visual>`` element of the link; None: all.
        source: ``"collision"`` or ``"visual"``.
        normal: cone axis in the link frame (any length: isf normalises it), or None.
        max_angle: cone half-angle, radians, in (0, pi].
        box_min, box_max: corners of the selection box in the link frame, metres, or None.
        points: number of surface points, in [1, MAX_POINTS].
        flip: flip the face normals (open sheets wound the wrong way).

    Raises:
        RegistrationError: a field is out of range (raised on construction).
    """

    name: str
    link: str
    geometry: str | None = None
    source: str = "collision"
    normal: tuple[float, float, float] | None = None
    max_angle: float = 0.5
    box_min: tuple[float, float, float] | None = None
    box_max: tuple[float, float, float] | None = None
    points: int = 256
    flip: bool = False

    def __post_init__(self) -> None:
        for attr in ("name", "link"):
            value = getattr(self, attr)
            if not isinstance(value, str) or not value.strip():
                raise RegistrationError(f"ContactSpec.{attr}={value!r} must be a non-empty string")
        if self.geometry is not None and (not isinstance(self.geometry, str) or not self.geometry):
            raise RegistrationError(
                f"ContactSpec.geometry={self.geometry!r} must be an element name or None"
            )
        if self.source not in ("collision", "visual"):
            raise RegistrationError(
                f"ContactSpec.source={self.source!r} must be 'collision' or 'visual'"
            )
        object.__setattr__(
            self, "normal", _vector(self.normal, "ContactSpec.normal", direction=True)
        )
        object.__setattr__(self, "box_min", _vector(self.box_min, "ContactSpec.box_min"))
        object.__setattr__(self, "box_max", _vector(self.box_max, "ContactSpec.box_max"))
        if self.box_min is not None and self.box_max is not None:
            if any(lo > hi for lo, hi in zip(self.box_min, self.box_max)):
                raise RegistrationError(
                    f"contact {self.name!r}: box_min {self.box_min} exceeds box_max "
                    f"{self.box_max} on some axis: swap them"
                )
        angle = float(self.max_angle)
        if not 0.0 < angle <= math.pi:
            raise RegistrationError(
                f"contact {self.name!r}: max_angle={self.max_angle!r} must lie in (0, pi] radians"
            )
        object.__setattr__(self, "max_angle", angle)
        if isinstance(self.points, bool) or not isinstance(self.points, (int, np.integer)) or not (
            1 <= self.points <= MAX_POINTS
        ):
            raise RegistrationError(
                f"contact {self.name!r}: points={self.points!r} must be an integer in "
                f"[1, {MAX_POINTS}] (a few hundred suffice)"
            )
        object.__setattr__(self, "points", int(self.points))
        if not isinstance(self.flip, (bool, np.bool_)):
            raise RegistrationError(f"contact {self.name!r}: flip={self.flip!r} must be a bool")
        object.__setattr__(self, "flip", bool(self.flip))

    @classmethod
    def parse(cls, text: str) -> ContactSpec:
        """A spec from ``key=value`` words, e.g. ``"name=left link=left_finger normal=0,-1,0"``.

        Keys are the field names; vectors are three comma-separated numbers; ``flip`` takes
        ``true``/``false``. Meant for command lines (``isf tag --contact ...``).

        Raises:
            RegistrationError: an unknown key, a word without ``=``, or a bad value.
        """
        fields = {f for f in cls.__dataclass_fields__}
        kwargs: dict = {}
        for word in text.split():
            key, eq, value = word.partition("=")
            if not eq or key not in fields:
                raise RegistrationError(
                    f"contact {text!r}: {word!r} is not key=value with a key among "
                    f"{', '.join(sorted(fields))}"
                )
            try:
                if key in ("normal", "box_min", "box_max"):
                    kwargs[key] = tuple(float(v) for v in value.split(","))
                elif key == "max_angle":
                    kwargs[key] = float(value)
                elif key == "points":
                    kwargs[key] = int(value)
                elif key == "flip":
                    kwargs[key] = {"true": True, "false": False}[value.lower()]
                else:
                    kwargs[key] = value
            except (ValueError, KeyError) as exc:
                raise RegistrationError(
                    f"contact {text!r}: bad value in {word!r}; vectors are x,y,z, "
                    "flip is true or false"
                ) from exc
        missing = [k for k in ("name", "link") if k not in kwargs]
        if missing:
            raise RegistrationError(f"contact {text!r} needs {' and '.join(missing)}=...")
        return cls(**kwargs)

    def to_xml(self) -> str:
        """The ``<isf:contact .../>`` element; default-valued attributes are left out."""
        attrs = [("name", self.name), ("link", self.link)]
        if self.geometry is not None:
            attrs.append(("geometry", self.geometry))
        if self.source != "collision":
            attrs.append(("source", self.source))
        if self.normal is not None:
            attrs.append(("normal", _format_vector(self.normal)))
        if self.max_angle != 0.5:
            attrs.append(("max_angle", _ATTR_FLOAT.format(self.max_angle)))
        if self.box_min is not None:
            attrs.append(("box_min", _format_vector(self.box_min)))
        if self.box_max is not None:
            attrs.append(("box_max", _format_vector(self.box_max)))
        if self.points != 256:
            attrs.append(("points", str(self.points)))
        if self.flip:
            attrs.append(("flip", "true"))
        return _element("contact", attrs)


def _format_vector(v) -> str:
    # round-off below 1e-12 becomes 0 so the file reads "0 0 1", not "1.49e-14 0 1"
    return " ".join(_ATTR_FLOAT.format(0.0 if abs(x) < 1e-12 else x) for x in v)


def _element(local: str, attrs: Sequence[tuple[str, str]]) -> str:
    return f"<isf:{local} " + " ".join(f"{k}={quoteattr(v)}" for k, v in attrs) + "/>"


# --------------------------------------------------------------- preview
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
        """
        from ..gripper.loading import load_gripper

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
            lift = 2e-4 * np.repeat(_face_normals(tris)[:, None, :], 3, axis=1)
            patch = trimesh.Trimesh(
                (tris + lift).reshape(-1, 3), np.arange(3 * len(tris)).reshape(-1, 3), process=False
            )
            patch.visual.face_colors = (220, 30, 30, 255)
            parts.append(patch)
        out = Path(path)
        trimesh.util.concatenate(parts).export(str(out))
        return out


def _mm(v: np.ndarray) -> str:
    return "(" + " ".join(f"{1e3 * x:7.2f}" for x in v) + ")"


def _dir(v: np.ndarray | None) -> str:
    return "-" if v is None else "(" + " ".join(f"{x:+.3f}" for x in v) + ")"


def _face_normals(tris: np.ndarray) -> np.ndarray:
    cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    return cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-300)[:, None]


def _face_areas(tris: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)


# ------------------------------------------------------------- text edits
_COMMENT = re.compile(r"<!--.*?-->", re.DOTALL)
_ROOT_OPEN = re.compile(r"<!--.*?-->|<\?.*?\?>|<!DOCTYPE[^>]*>|<([A-Za-z_][\w.:\-]*)", re.DOTALL)
_ROBOT_CLOSE = re.compile(r"</robot\s*>")
_ISF_XMLNS = re.compile(r"""\sxmlns:isf\s*=\s*(["'])(.*?)\1""", re.DOTALL)
_ISF_ELEMENT = re.compile(
    r"[ \t]*<isf:(\w+)\b(?:[^>\"']|\"[^\"]*\"|'[^']*')*?/>[ \t]*(?:\r?\n)?"
    r"|[ \t]*<isf:(\w+)\b[^>]*>.*?</isf:\2\s*>[ \t]*(?:\r?\n)?",
    re.DOTALL,
)
_MESH_TAG = re.compile(r"<mesh\b(?:[^>\"']|\"[^\"]*\"|'[^']*')*>")
_FILENAME_ATTR = re.compile(r"""(\bfilename\s*=\s*)(["'])(.*?)\2""", re.DOTALL)
_XML_ENTITIES = {"&quot;": '"', "&apos;": "'"}


def _comment_spans(text: str) -> list[tuple[int, int]]:
    return [m.span() for m in _COMMENT.finditer(text)]


def _in_spans(pos: int, spans: list[tuple[int, int]]) -> bool:
    return any(a <= pos < b for a, b in spans)


def _root_start_tag(text: str) -> tuple[int, int]:
    """Span ``(start, end)`` of the ``<robot ...>`` start tag; ``end`` is just past its ``>``."""
    opening = next((m for m in _ROOT_OPEN.finditer(text) if m.group(1)), None)
    if opening is None or opening.group(1) != "robot":
        found = None if opening is None else opening.group(1)
        raise RegistrationError(f"not a URDF: the root element is <{found}>, expected <robot>")
    quote = None
    for i in range(opening.end(), len(text)):
        ch = text[i]
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch == ">":
            return opening.start(), i + 1
    raise RegistrationError("the <robot> start tag is never closed: fix the file's syntax")


def _declare_namespace(text: str) -> tuple[str, bool]:
    """Declare ``xmlns:isf`` on ``<robot>``; return the text and whether it was added."""
    start, end = _root_start_tag(text)
    tag = text[start:end]
    bound = _ISF_XMLNS.search(tag)
    if bound is not None:
        if bound.group(2) != ISF_NS:
            raise RegistrationError(
                f"the URDF binds xmlns:isf to {bound.group(2)!r}: bind it to {ISF_NS!r} "
                "(version 1 of the convention) or remove the declaration"
            )
        return text, False
    close = end - 2 if tag.endswith("/>") else end - 1
    while close > start and text[close - 1].isspace():
        close -= 1
    return text[:close] + f' xmlns:isf="{ISF_NS}"' + text[close:], True


def _remove_isf_elements(text: str) -> str:
    spans = _comment_spans(text)
    out, last = [], 0
    for m in _ISF_ELEMENT.finditer(text):
        if _in_spans(m.start(), spans):
            continue
        out.append(text[last : m.start()])
        last = m.end()
    return "".join(out) + text[last:]


def _insert_elements(text: str, elements: Sequence[str]) -> str:
    """Insert ``elements`` (one per line) just before the last ``</robot>``."""
    spans = _comment_spans(text)
    closes = [m for m in _ROBOT_CLOSE.finditer(text) if not _in_spans(m.start(), spans)]
    if not closes:
        raise RegistrationError("the URDF has no </robot> end tag: fix the file's syntax")
    at = closes[-1].start()
    newline = "\r\n" if "\r\n" in text else "\n"
    _, root_end = _root_start_tag(text)
    child = re.compile(r"\n([ \t]*)<").search(text, root_end)
    indent = child.group(1) if child and child.group(1) else "  "
    block = "".join(f"{indent}{e}{newline}" for e in elements)
    line_start = text.rfind("\n", 0, at) + 1
    if text[line_start:at].strip() == "":
        return text[:line_start] + block + text[line_start:]
    return text[:at] + newline + block + text[at:]


def _attr_value(raw: str) -> str:
    return unescape(raw, _XML_ENTITIES)


def _mesh_rewrites(
    text: str, src_dir: Path, dst_dir: Path, package_dirs: PackageDirs | None
) -> dict[str, str]:
    """``{filename: absolute path}`` for every mesh name that the copy would not resolve."""
    spans = _comment_spans(text)
    out: dict[str, str] = {}
    for tag in _MESH_TAG.finditer(text):
        attr = _FILENAME_ATTR.search(tag.group(0))
        if attr is None or _in_spans(tag.start(), spans):
            continue
        name = _attr_value(attr.group(3))
        if name in out:
            continue
        try:
            target = resolve_mesh_path(name, src_dir, package_dirs)
        except MeshNotFoundError:
            continue  # validation reports it
        seen = next((p for p in mesh_path_candidates(name, dst_dir) if p.is_file()), None)
        if seen is None or not os.path.samefile(seen, target):
            out[name] = str(target)
    return out


def _apply_rewrites(text: str, rewrites: Mapping[str, str]) -> str:
    if not rewrites:
        return text
    spans = _comment_spans(text)

    def fix_tag(tag: re.Match) -> str:
        if _in_spans(tag.start(), spans):
            return tag.group(0)

        def fix_attr(attr: re.Match) -> str:
            new = rewrites.get(_attr_value(attr.group(3)))
            if new is None:
                return attr.group(0)
            q = attr.group(2)
            value = escape(new, {q: "&quot;" if q == '"' else "&apos;"})
            return f"{attr.group(1)}{q}{value}{q}"

        return _FILENAME_ATTR.sub(fix_attr, tag.group(0), count=1)

    return _MESH_TAG.sub(fix_tag, text)


# ------------------------------------------------------------- kinematics
def _read_urdf(urdf_path: str | Path) -> tuple[Path, str]:
    path = Path(urdf_path).expanduser()
    if not path.is_file():
        raise RegistrationError(f"{str(urdf_path)!r} is not a file: give the path of a .urdf file")
    try:
        return path.resolve(), path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RegistrationError(
            f"{path} is not UTF-8 text ({exc}): convert the file to UTF-8"
        ) from exc


def _parse(text: str, path: Path) -> TaggedURDF:
    try:
        return parse_tagged_urdf(text)
    except URDFReadError as exc:
        raise RegistrationError(f"{path}: {exc}") from exc


def _initial_tags(initial: Mapping[str, float] | None) -> tuple[InitialTag, ...]:
    if initial is None:
        return ()
    if not isinstance(initial, Mapping):
        raise RegistrationError(
            f"initial={initial!r} must map joint names to values, e.g. {{'finger_joint': 0.02}}"
        )
    tags = []
    for joint, value in initial.items():
        try:
            value = float(value)
        except (TypeError, ValueError):
            value = math.nan
        if not isinstance(joint, str) or not math.isfinite(value):
            raise RegistrationError(
                f"initial[{joint!r}]={initial[joint]!r}: give a joint name and a finite value "
                "in metres or radians"
            )
        tags.append(InitialTag(joint, value))
    return tuple(tags)


@dataclass(frozen=True, eq=False)
class _Posed:
    """A URDF's model at its initial configuration."""

    doc: TaggedURDF
    model: pin.Model
    q: np.ndarray
    poses: dict[str, np.ndarray]  # T_root_link of every link


def _posed(text: str, doc: TaggedURDF, initial: tuple[InitialTag, ...]) -> _Posed:
    """Build the model and place every link at the initial configuration.

    Raises:
        ModelBuildError: Pinocchio cannot build the model.
    """
    model = build_model(text, doc)
    overridden = {t.joint for t in initial}
    kept = tuple(t for t in doc.initial if t.joint not in overridden)
    doc_q = replace(doc, initial=kept + initial)
    q = initial_configuration(model, doc_q)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    poses = {
        f.name: data.oMf[i].homogeneous.copy()
        for i, f in enumerate(model.frames)
        if f.type == pin.FrameType.BODY
    }
    return _Posed(doc_q, model, q, poses)


def _joint_values(posed: _Posed) -> dict[str, float]:
    model = posed.model
    return {
        model.names[j]: float(posed.q[model.joints[j].idx_q])
        for j in range(1, model.njoints)
        if model.joints[j].nq > 0
    }


# ------------------------------------------------------------------ preview
def _surface_preview(
    tag: ContactTag,
    doc: TaggedURDF,
    urdf_dir: Path,
    posed: _Posed | None,
    report_problems: list[str],
    cache: dict,
) -> SurfacePreview:
    problems = [p for p in report_problems if p.startswith(f"contact {tag.name!r}")]
    base = SurfacePreview(tag.name, tag.link, tag.source, problems=tuple(problems))
    link = doc.links.get(tag.link)
    if link is None:
        return base  # the report names the missing link
    try:
        elements = tag_elements(tag, link)
        meshes = [load_geometry(e, urdf_dir, None, cache) for e in elements]
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


# ---------------------------------------------------------------- tag_urdf
def _gripper_element(palm_link: str | None, approach) -> str | None:
    attrs = []
    if palm_link is not None:
        if not isinstance(palm_link, str) or not palm_link:
            raise RegistrationError(f"palm_link={palm_link!r} must be a link name")
        attrs.append(("palm_link", palm_link))
    approach = _vector(approach, "approach", direction=True)
    if approach is not None:
        unit = np.asarray(approach) / np.linalg.norm(approach)
        attrs.append(("approach", _format_vector(unit)))
    return _element("gripper", attrs) if attrs else None


def tag_urdf(
    urdf_path: str | Path,
    out_path: str | Path,
    contacts: Sequence[ContactSpec],
    *,
    palm_link: str | None = None,
    approach: Sequence[float] | None = None,
    initial: Mapping[str, float] | None = None,
    package_dirs: PackageDirs | None = None,
    replace_tags: bool = False,
) -> TagPreview:
    """Write a tagged copy of a URDF, validate it and show what every tag selected.

    The source file is only read. The copy equals it byte for byte apart from the
    ``xmlns:isf`` declaration, the ``isf:*`` lines inserted before ``</robot>`` and mesh
    filenames that must become absolute for the copy to find them (module docstring).

    Args:
        urdf_path: the stock URDF.
        out_path: the copy to write (parent folders are created); must not be ``urdf_path``.
        contacts: the contact surfaces to tag (at least one), e.g. from :func:`suggest_contacts`.
        palm_link: optional ``<isf:gripper palm_link>``; default: the root link.
        approach: optional approach direction in the palm link frame (any length).
        initial: optional initial values of actuated joints, metres or radians.
        package_dirs: optional ``{package: folder}`` map for ``package://`` paths of the source.
        replace_tags: drop ``isf:*`` elements the source already has instead of refusing.

    Returns:
        the :class:`TagPreview`; ``preview.ok`` is True when the copy loads.

    Raises:
        RegistrationError: bad arguments, an unreadable source, an existing ``isf:*`` tag
            (without ``replace_tags``), or ``out_path`` naming the source.
    """
    t0 = time.perf_counter()
    src, text = _read_urdf(urdf_path)
    dst = Path(out_path).expanduser().absolute()
    if dst.exists() and os.path.samefile(dst, src):
        raise RegistrationError(
            f"out_path {dst} is the source file; isf never edits the vendor file: "
            "write the copy under another name"
        )
    contacts = list(contacts)
    if not contacts or not all(isinstance(c, ContactSpec) for c in contacts):
        raise RegistrationError(
            "contacts must be a non-empty sequence of ContactSpec, e.g. suggest_contacts(urdf)"
        )
    names = [c.name for c in contacts]
    dups = sorted({n for n in names if names.count(n) > 1})
    if dups:
        raise RegistrationError(f"contact names {dups} are used more than once: make them unique")
    gripper = _gripper_element(palm_link, approach)
    initial_tags = _initial_tags(initial)

    doc = _parse(text, src)
    if doc.contacts or doc.gripper or doc.initial or re.search(r"<isf:", _COMMENT.sub("", text)):
        if not replace_tags:
            raise RegistrationError(
                f"{src} already has isf:* tags: pass replace_tags=True (CLI: --replace) to "
                "drop them, or tag the untagged vendor file"
            )
        text = _remove_isf_elements(text)
    new, added = _declare_namespace(text)
    rewrites = _mesh_rewrites(new, src.parent, dst.parent, package_dirs)
    new = _apply_rewrites(new, rewrites)
    elements = [gripper] if gripper else []
    elements += [c.to_xml() for c in contacts]
    elements += [
        _element("initial", [("joint", t.joint), ("value", _ATTR_FLOAT.format(t.value))])
        for t in initial_tags
    ]
    new = _insert_elements(new, elements)
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_bytes(new.encode("utf-8"))
    t1 = time.perf_counter()
    log.info(
        "wrote %s (%d isf elements, %d mesh paths made absolute)",
        dst,
        len(elements),
        len(rewrites),
    )

    report = inspect_gripper(dst)
    new_doc = parse_tagged_urdf(new)
    try:
        posed = _posed(new, new_doc, ())
    except ModelBuildError:
        posed = None  # the report says why
    cache: dict = {}
    surfaces = tuple(
        _surface_preview(tag, new_doc, dst.parent, posed, report.problems, cache)
        for tag in new_doc.contacts
    )
    return TagPreview(
        source_path=src,
        urdf_path=dst,
        surfaces=surfaces,
        report=report,
        rewritten_meshes=rewrites,
        namespace_added=added,
        q_initial={} if posed is None else _joint_values(posed),
        tag_time=t1 - t0,
        validation_time=time.perf_counter() - t1,
    )


# --------------------------------------------------------- suggestions
@dataclass(frozen=True, eq=False)
class _Fingertip:
    link: str
    source: str
    meshes: tuple[trimesh.Trimesh, ...]  # link frame
    centroid: np.ndarray  # gripper frame, (3,)


def _movable_depth(doc: TaggedURDF) -> dict[str, int]:
    """Number of movable joints between the root and every link."""
    parent = {j.child: j for j in doc.joints.values()}
    depth: dict[str, int] = {}
    for link in doc.links:
        n, x, seen = 0, link, set()
        while x in parent and x not in seen:
            seen.add(x)
            n += parent[x].type in _MOVABLE
            x = parent[x].parent
        depth[link] = n
    return depth


def _surface_centroid(meshes: Sequence[trimesh.Trimesh]) -> np.ndarray:
    tris = np.concatenate([np.asarray(m.triangles) for m in meshes])
    areas = _face_areas(tris)
    if areas.sum() <= 0:
        return tris.reshape(-1, 3).mean(axis=0)
    return areas @ tris.mean(axis=1) / areas.sum()


def _fingertip_candidates(doc: TaggedURDF, links: Sequence[str] | None) -> list[str]:
    """Leaf links below a movable joint (or ``links``), each replaced by its nearest
    ancestor with geometry when it has none itself."""
    parent = {j.child: j.parent for j in doc.joints.values()}
    depth = _movable_depth(doc)
    if links is not None:
        missing = [name for name in links if name not in doc.links]
        if missing:
            raise RegistrationError(
                f"links {missing} do not exist in the URDF; links: {', '.join(doc.links)}"
            )
        return list(dict.fromkeys(links))
    has_child = {j.parent for j in doc.joints.values()}
    out: dict[str, None] = {}
    for leaf in doc.links:
        if leaf in has_child or depth[leaf] == 0:
            continue
        x = leaf
        while not (doc.links[x].collisions or doc.links[x].visuals) and x in parent:
            x = parent[x]
        if depth[x] > 0 and (doc.links[x].collisions or doc.links[x].visuals):
            out.setdefault(x, None)
    return list(out)


def _fingertips(
    urdf_path: str | Path,
    links: Sequence[str] | None,
    initial: Mapping[str, float] | None,
    package_dirs: PackageDirs | None,
) -> tuple[_Posed, list[_Fingertip]]:
    src, text = _read_urdf(urdf_path)
    doc = _parse(text, src)
    try:
        posed = _posed(text, doc, _initial_tags(initial))
    except ModelBuildError as exc:
        raise RegistrationError(f"{src}: {exc}") from exc
    cache: dict = {}
    tips = []
    for name in _fingertip_candidates(doc, links):
        link = doc.links[name]
        source = "collision" if link.collisions else "visual"
        try:
            meshes = tuple(
                load_geometry(e, src.parent, package_dirs, cache)
                for e in (link.collisions or link.visuals)
            )
        except (GeometryLoadError, MeshNotFoundError) as exc:
            raise RegistrationError(f"link {name!r}: {exc}") from exc
        if not meshes:
            raise RegistrationError(
                f"link {name!r} has no geometry to put a contact on: choose other links"
            )
        T = posed.poses[name]
        centroid = T[:3, :3] @ _surface_centroid(meshes) + T[:3, 3]
        tips.append(_Fingertip(name, source, meshes, centroid))
    if links is None:
        tips = _drop_side_links(tips, _movable_depth(doc))
    if len(tips) < 2:
        found = ", ".join(t.link for t in tips) or "none"
        raise RegistrationError(
            f"{src}: found {len(tips)} fingertip link(s) ({found}); a grasp needs at least two: "
            "pass links=[...] naming the fingertip links"
        )
    return posed, tips


def _drop_side_links(tips: list[_Fingertip], depth: dict[str, int]) -> list[_Fingertip]:
    """Drop leaves of linkages (e.g. a four-bar's inner knuckle): a leaf with fewer movable
    joints than another leaf and much nearer to the root than it."""
    reach = {t.link: float(np.linalg.norm(t.centroid)) for t in tips}
    keep = []
    for t in tips:
        beaten = [
            u.link
            for u in tips
            if depth[u.link] > depth[t.link] and reach[t.link] < _SIDE_LINK_RATIO * reach[u.link]
        ]
        if beaten:
            log.info("not a fingertip: %s (nearer than %s, fewer joints)", t.link, beaten[0])
        else:
            keep.append(t)
    return keep


def _facing_normal(
    meshes: Sequence[trimesh.Trimesh], direction: np.ndarray
) -> tuple[np.ndarray, bool]:
    """The face normal of ``meshes`` (link frame) that faces ``direction``, and whether it
    belongs to a flat pad.

    Faces within ``_SEARCH_ANGLE`` of ``direction`` are considered; the largest cluster of
    nearly parallel normals (a flat pad) gives the answer when it holds at least half their
    area. Otherwise (a rounded tip) ``direction`` itself is returned.
    """
    tris = np.concatenate([np.asarray(m.triangles) for m in meshes])
    normals, areas = _face_normals(tris), _face_areas(tris)
    near = (normals @ direction >= math.cos(_SEARCH_ANGLE)) & (areas > 0)
    if not near.any():
        return direction, False
    n, a = normals[near], areas[near]
    seeds = np.arange(len(n))
    if len(seeds) > _MAX_CLUSTER_SEEDS:
        seeds = np.argsort(-a)[:_MAX_CLUSTER_SEEDS]
    support = (n[seeds] @ n.T >= math.cos(_CLUSTER_ANGLE)) @ a
    best = seeds[int(np.argmax(support))]
    members = n @ n[best] >= math.cos(_CLUSTER_ANGLE)
    if a[members].sum() < _FLAT_SHARE * a.sum():
        return direction, False
    mean = a[members] @ n[members]
    return mean / np.linalg.norm(mean), True


def _closing_direction(posed: _Posed, link: str, toward: np.ndarray) -> np.ndarray:
    """``toward`` (unit, gripper frame) without its component along the axis of the revolute
    joint that moves ``link`` last, (3,): a rounded fingertip faces the side its finger curls
    towards, not sideways out of the finger (on a hand the centroid of the fingertips lies off to
    the side of most fingers). Unchanged when that joint is prismatic or the rest is too small.
    """
    model = posed.model
    fid = model.getFrameId(link)
    joint = model.frames[fid].parentJoint
    if joint == 0 or model.joints[joint].nv == 0:
        return toward
    J = pin.computeFrameJacobian(model, model.createData(), posed.q, fid, pin.LOCAL_WORLD_ALIGNED)
    column = J[3:, model.joints[joint].idx_v]
    if np.linalg.norm(column) < 1e-9:  # a prismatic joint turns nothing
        return toward
    axis = column / np.linalg.norm(column)
    rest = toward - (toward @ axis) * axis
    norm = float(np.linalg.norm(rest))
    return rest / norm if norm > 0.2 else toward


def _surface_name(link: str) -> str:
    return link if link.endswith(("pad", "tip")) else f"{link}_pad"


def _distal_box(
    spec: ContactSpec, meshes: Sequence[trimesh.Trimesh], reach: np.ndarray, fraction: float
) -> ContactSpec:
    """Restrict a flat pad to its faces that lie wholly in the distal ``fraction`` of its length.

    ``reach`` is the approach direction in the link frame (unit). The cut is a bound on the link
    axis nearest ``reach``, written as ``box_min``/``box_max`` (other axes: the link's geometry
    bounds widened by 1 cm). A box keeps faces by their centroids, so the bound sits between the
    centroids of the distal faces and that of the first face reaching further back; vendor
    collision meshes often hold long sliver faces, which this leaves out. Nothing changes when
    no link axis lies within 20 degrees of ``reach`` or when the most distal face already
    reaches further back (a box face of two triangles).
    """
    axis = int(np.argmax(np.abs(reach)))
    if abs(reach[axis]) < math.cos(_DISTAL_AXIS_ANGLE):
        return spec
    axis_n = np.asarray(spec.normal) / np.linalg.norm(spec.normal)
    tag = ContactTag(spec.name, spec.link, normal=axis_n, max_angle=spec.max_angle)
    tris = select_faces(tag, meshes).triangles
    sign = 1.0 if reach[axis] > 0 else -1.0
    along = sign * tris[:, :, axis]  # larger is more distal
    limit = along.max() - fraction * (along.max() - along.min()) - 1e-9
    centroids = along.mean(axis=1)
    order = np.argsort(-centroids)
    inside = along[order].min(axis=1) >= limit
    n_keep = len(order) if inside.all() else int(np.argmin(inside))
    if n_keep == 0 or n_keep == len(order):
        return spec
    first_out, last_in = centroids[order[n_keep]], centroids[order[n_keep - 1]]
    cut = round(0.5 * (first_out + last_in), 4)  # a readable value between the two centroids
    if not first_out < cut < last_in:
        cut = 0.5 * (first_out + last_in)
    verts = np.concatenate([np.asarray(m.vertices) for m in meshes])
    bound_lo = np.floor(1e3 * (verts.min(axis=0) - _BOX_MARGIN)) / 1e3
    bound_hi = np.ceil(1e3 * (verts.max(axis=0) + _BOX_MARGIN)) / 1e3
    if sign > 0:
        bound_lo[axis] = cut
    else:
        bound_hi[axis] = -cut
    return replace(spec, box_min=tuple(bound_lo), box_max=tuple(bound_hi))


def suggest_contacts(
    urdf_path: str | Path,
    *,
    links: Sequence[str] | None = None,
    initial: Mapping[str, float] | None = None,
    package_dirs: PackageDirs | None = None,
    points: int = 256,
    max_angle: float | None = None,
    tip_fraction: float = 0.5,
) -> list[ContactSpec]:
    """Propose one contact surface per fingertip, facing the other fingertips.

    Fingertips: the leaf links of the kinematic tree that lie below at least one movable
    joint (a leaf without geometry is replaced by its nearest ancestor with some). A leaf
    that has fewer movable joints than another leaf and is less than 0.75 times as far from
    the root is taken for a linkage side link (the inner knuckle of a four-bar finger) and
    dropped. ``links`` overrides all of this.

    Facing direction: at the initial configuration (``isf:initial`` tags, then ``initial``,
    else mid-limits), the direction from the fingertip's geometry centroid to the centroid
    of all fingertips, in the link frame. The contact's ``normal`` is the mean normal of the
    largest flat cluster of faces within 46 degrees of it (a pad); when no cluster holds half
    of those faces' area (a rounded tip) it is that direction without its component along
    the axis of the revolute joint that moves the tip last, i.e. the side the finger curls
    towards (on a hand the centroid lies off to the side of most fingers; a cap facing
    sideways would put the distal link's edge into the object). The cone half-angle
    ``max_angle`` is 0.3 rad for a flat pad (its faces only) and 0.5 rad for a rounded tip
    (a cap of it). Collision geometry is used when the link has any, else visual geometry.

    Fingertip part of a flat pad: ISF pulls a contact surface onto the object as a whole, so a
    pad as long as the finger (Franka hand) puts the palm into any object longer than the pad.
    A flat pad is therefore cut to the ``tip_fraction`` of its length at its distal end (along
    the approach direction, the root origin to the fingertips' centroid): only its faces lying
    wholly in that part are kept, with a ``box_min``/``box_max``. A pad whose most distal face
    already reaches further back (a box face of two triangles) is kept whole.

    Args:
        urdf_path: the URDF (tagged or not).
        links: fingertip links to use instead of the automatic choice.
        initial: initial joint values by name, metres or radians.
        package_dirs: optional ``{package: folder}`` map for ``package://`` mesh paths.
        points: ``points`` of every proposed contact.
        max_angle: ``max_angle`` of every proposed contact, radians; None: automatic.
        tip_fraction: share of a flat pad's length kept at its distal end, in (0, 1];
            1 keeps the whole pad.

    Returns:
        one :class:`ContactSpec` per fingertip, named after its link (``<link>_pad`` unless
        the link name already ends in ``pad`` or ``tip``).

    Raises:
        RegistrationError: unreadable URDF or meshes, unknown ``links``, fewer than two
            fingertips, fingertips that coincide at the initial configuration, or a bad
            ``tip_fraction``.
    """
    if not 0.0 < tip_fraction <= 1.0:
        raise RegistrationError(f"tip_fraction={tip_fraction!r} must lie in (0, 1]")
    posed, tips = _fingertips(urdf_path, links, initial, package_dirs)
    center = np.mean([t.centroid for t in tips], axis=0)
    reach = center / max(float(np.linalg.norm(center)), 1e-300)  # root origin -> fingertips
    out = []
    for t in tips:
        toward = center - t.centroid
        dist = float(np.linalg.norm(toward))
        if dist < 1e-4:
            raise RegistrationError(
                f"fingertip {t.link!r} sits at the centroid of all fingertips at the initial "
                "configuration, so it faces no direction: pass initial={...} with the gripper open"
            )
        R = posed.poses[t.link][:3, :3]
        normal, flat = _facing_normal(t.meshes, R.T @ toward / dist)
        if not flat:  # a rounded tip: face the side the finger closes towards
            normal = R.T @ _closing_direction(posed, t.link, toward / dist)
        auto_angle = _PAD_ANGLE if flat else _TIP_ANGLE
        spec = ContactSpec(
            name=_surface_name(t.link),
            link=t.link,
            source=t.source,
            normal=tuple(np.round(normal, 4)),
            max_angle=auto_angle if max_angle is None else max_angle,
            points=points,
        )
        if flat and tip_fraction < 1.0 and np.linalg.norm(center) > 1e-6:
            spec = _distal_box(spec, t.meshes, R.T @ reach, tip_fraction)
        out.append(spec)
    return out


def suggest_approach(
    urdf_path: str | Path,
    *,
    palm_link: str | None = None,
    links: Sequence[str] | None = None,
    initial: Mapping[str, float] | None = None,
    package_dirs: PackageDirs | None = None,
) -> tuple[float, float, float]:
    """Propose ``<isf:gripper approach>``: from the palm link origin toward the fingertips.

    Args:
        urdf_path: the URDF.
        palm_link: the link the direction is expressed in; default the root link.
        links, initial, package_dirs: as for :func:`suggest_contacts`.

    Returns:
        unit direction in the ``palm_link`` frame, from its origin to the centroid of the
        fingertips' geometry at the initial configuration.

    Raises:
        RegistrationError: as :func:`suggest_contacts`, or an unknown ``palm_link``.
    """
    posed, tips = _fingertips(urdf_path, links, initial, package_dirs)
    palm = palm_link or posed.doc.root_link
    if palm not in posed.poses:
        raise RegistrationError(
            f"palm_link {palm!r} does not exist; links: {', '.join(posed.doc.links)}"
        )
    T = posed.poses[palm]
    center = np.mean([t.centroid for t in tips], axis=0)
    v = T[:3, :3].T @ (center - T[:3, 3])
    norm = float(np.linalg.norm(v))
    if norm < 1e-6:
        raise RegistrationError(
            f"the fingertips surround the origin of {palm!r}: give approach=... yourself"
        )
    return tuple(float(x) for x in v / norm)
