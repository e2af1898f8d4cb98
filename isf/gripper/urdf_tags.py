"""Read a tagged URDF's text: links, joints, geometry elements and the ``isf:*`` tags.

Only the standard library's ElementTree is used. Vendor files often use XML
prefixes they never declare (the Robotiq 2F-85 URDF writes ``drake:`` elements);
such prefixes are declared on the root tag before parsing, so the rest of the
file stays readable. An undeclared ``isf:`` prefix is declared the same way (the
tags are still read) but reported as a problem, because strict parsers such as
lxml reject or drop those elements.

Everything that is wrong but not fatal is collected in
:attr:`TaggedURDF.problems`, one message per problem naming the fix.
"""

from __future__ import annotations

import contextlib
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from xml.parsers import expat

import numpy as np

from ..exceptions import URDFReadError

__all__ = [
    "ISF_NS",
    "MAX_POINTS",
    "ClosingTag",
    "ContactTag",
    "GeometryElement",
    "GripperTag",
    "InitialTag",
    "JointElement",
    "LinkElement",
    "Mimic",
    "TaggedURDF",
    "URDFReadError",
    "parse_tagged_urdf",
    "rpy_matrix",
]

ISF_NS = "urn:isf:gripper:1"
"""Namespace URI of version 1 of the isf tag convention."""

_CONTACT_ATTRS = (
    "name",
    "link",
    "geometry",
    "source",
    "normal",
    "max_angle",
    "box_min",
    "box_max",
    "points",
    "flip",
)
_GRIPPER_ATTRS = ("palm_link", "approach", "tcp_link", "tcp_origin")
MAX_POINTS = 10_000
"""Largest ``points`` a contact tag may ask for (farthest-point ordering is O(points^2))."""
_INITIAL_ATTRS = ("joint", "value")
_CLOSING_ATTRS = ("joint", "sign")


# ---------------------------------------------------------------- structures
@dataclass(frozen=True, eq=False)
class GeometryElement:
    """One ``<collision>`` or ``<visual>`` element of a link.

    Attributes:
        link: the link that carries it.
        name: its ``name`` attribute, or ``<link>_<k>`` for the k-th element of its kind.
        source: ``"collision"`` or ``"visual"``.
        index: k, its position among the link's elements of the same kind.
        shape: ``"mesh"``, ``"box"``, ``"cylinder"``, ``"sphere"``, another tag name
            (unsupported), or None when ``<geometry>`` is missing or empty.
        T_link_geom: pose of the element in the link frame (its ``<origin>``), (4, 4).
        filename: mesh filename as written (meshes only).
        scale: mesh scale per axis, shape (3,).
        size: box edge lengths, metres, shape (3,) (boxes only).
        radius: cylinder or sphere radius, metres.
        length: cylinder length along z, metres.
    """

    link: str
    name: str
    source: str
    index: int
    shape: str | None
    T_link_geom: np.ndarray
    filename: str | None = None
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    size: np.ndarray | None = None
    radius: float | None = None
    length: float | None = None


@dataclass(frozen=True)
class LinkElement:
    """A ``<link>``: its name and geometry elements in file order."""

    name: str
    collisions: tuple[GeometryElement, ...]
    visuals: tuple[GeometryElement, ...]


@dataclass(frozen=True)
class Mimic:
    """A ``<mimic>``: ``q_this = multiplier * q_leader + offset``."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class JointElement:
    """A ``<joint>``; limits are None when the ``<limit>`` attribute is absent.

    Attributes:
        axis: the ``<axis xyz>`` as written (URDF's default ``1 0 0`` when absent), in the
            joint frame; None when it is not three finite numbers (a problem is recorded).
    """

    name: str
    type: str
    parent: str
    child: str
    lower: float | None
    upper: float | None
    mimic: Mimic | None
    axis: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class ContactTag:
    """An ``<isf:contact>`` (see docs/gripper-tags.md); vectors are in the link frame.

    Attributes:
        normal: unit cone axis, shape (3,), or None.
        box_min, box_max: selection box corners, metres, shape (3,), or None.
    """

    name: str
    link: str
    geometry: str | None = None
    source: str = "collision"
    normal: np.ndarray | None = None
    max_angle: float = 0.5
    box_min: np.ndarray | None = None
    box_max: np.ndarray | None = None
    points: int = 256
    flip: bool = False


@dataclass(frozen=True, eq=False)
class GripperTag:
    """The ``<isf:gripper>`` tag; ``approach`` is a unit vector (3,) or None.

    Attributes:
        tcp_link: the link the tool-centre point is declared in (``tcp_link``), or None.
        T_link_tcp: the pose of the tool-centre-point frame in ``tcp_link``'s frame, (4, 4),
            from ``tcp_origin="x y z [roll pitch yaw]"`` (metres, radians, URDF's fixed-axis
            roll-pitch-yaw); the identity when only ``tcp_link`` is given, None without it.
    """

    palm_link: str | None = None
    approach: np.ndarray | None = None
    tcp_link: str | None = None
    T_link_tcp: np.ndarray | None = None


@dataclass(frozen=True)
class InitialTag:
    """An ``<isf:initial>`` tag: the joint's initial value, metres or radians."""

    joint: str
    value: float


@dataclass(frozen=True)
class ClosingTag:
    """An ``<isf:closing>`` tag: the sign (+1 or -1) of the joint's motion that closes its finger,
    or 0 for a joint that holds its value while the fingers close."""

    joint: str
    sign: float


@dataclass(eq=False)
class TaggedURDF:
    """Everything read from a tagged URDF's text.

    Attributes:
        robot_name: the ``<robot name>``.
        links: links by name, file order.
        joints: joints by name, file order.
        root_link: the only link that is no joint's child, or None if not unique.
        contacts, gripper, initial, closing: the isf tags.
        problems: one message per problem found while reading.
        root: the parsed ``<robot>`` element (every undeclared prefix declared).
    """

    robot_name: str
    links: dict[str, LinkElement]
    joints: dict[str, JointElement]
    root_link: str | None
    contacts: tuple[ContactTag, ...]
    gripper: GripperTag | None
    initial: tuple[InitialTag, ...]
    problems: list[str]
    root: ET.Element | None = field(default=None, repr=False)
    closing: tuple[ClosingTag, ...] = ()


# ------------------------------------------------------------------ helpers
_TAG_PREFIX = re.compile(r"</?([A-Za-z_][\w.\-]*):[A-Za-z_]")
_ATTR_PREFIX = re.compile(r"\s([A-Za-z_][\w.\-]*):[A-Za-z_][\w.\-]*\s*=")
_DECLARED = re.compile(r"xmlns:([A-Za-z_][\w.\-]*)\s*=")
_ROOT_TAG = re.compile(r"<!--.*?-->|<\?.*?\?>|<!DOCTYPE[^>]*>|<([A-Za-z_][\w.:\-]*)", re.DOTALL)


def _declare_missing_prefixes(text: str) -> tuple[str, list[str]]:
    """Declare on the root tag every XML prefix the text uses but never declares."""
    used = set(_TAG_PREFIX.findall(text)) | set(_ATTR_PREFIX.findall(text))
    missing = sorted(used - set(_DECLARED.findall(text)) - {"xml", "xmlns"})
    if not missing:
        return text, []
    root = next((m for m in _ROOT_TAG.finditer(text) if m.group(1)), None)
    if root is None:
        return text, missing
    decl = "".join(
        f' xmlns:{p}="{ISF_NS if p == "isf" else "urn:isf:undeclared:" + p}"' for p in missing
    )
    return text[: root.end()] + decl + text[root.end() :], missing


def rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw (fixed axes x, y, z) as a rotation matrix, (3, 3)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


class _Reader:
    """Number parsing that records a problem instead of raising."""

    def __init__(self) -> None:
        self.problems: list[str] = []

    def vector(self, text: str | None, where: str, n: int = 3) -> np.ndarray | None:
        if text is None:
            return None
        try:
            values = np.array([float(v) for v in text.split()])
        except ValueError:
            values = np.array([])
        if values.shape != (n,) or not np.all(np.isfinite(values)):
            self.problems.append(f"{where}={text!r} must be {n} finite numbers separated by spaces")
            return None
        return values

    def number(self, text: str | None, where: str) -> float | None:
        if text is None:
            return None
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            self.problems.append(f"{where}={text!r} must be a finite number")
            return None
        return value

    def origin(self, elem: ET.Element, where: str) -> np.ndarray:
        T = np.eye(4)
        origin = elem.find("origin")
        if origin is not None:
            xyz = self.vector(origin.get("xyz", "0 0 0"), f"{where} <origin xyz>")
            rpy = self.vector(origin.get("rpy", "0 0 0"), f"{where} <origin rpy>")
            T[:3, 3] = xyz if xyz is not None else 0.0
            T[:3, :3] = rpy_matrix(rpy if rpy is not None else np.zeros(3))
        return T


# ------------------------------------------------------------ URDF elements
def _geometry(rd: _Reader, link: str, elem: ET.Element, source: str, k: int) -> GeometryElement:
    name = elem.get("name") or f"{link}_{k}"
    where = f"link {link!r} <{source}> {name!r}"
    T = rd.origin(elem, where)
    geom = elem.find("geometry")
    shape_elem = None if geom is None else next(iter(geom), None)
    if shape_elem is None:
        rd.problems.append(
            f"{where} has no <geometry> shape; urdfdom then drops every {source} of the "
            "link: add a <mesh>/<box>/<cylinder>/<sphere> or remove the element"
        )
        return GeometryElement(link, name, source, k, None, T)
    shape, a = shape_elem.tag, shape_elem.attrib
    if shape == "mesh":
        scale = rd.vector(a.get("scale", "1 1 1"), f"{where} <mesh scale>")
        if scale is not None and not np.all(scale != 0):
            rd.problems.append(f"{where} <mesh scale={a.get('scale')!r}> has a zero factor, which "
                               "flattens the mesh: give three non-zero factors (negative mirrors)")
            scale = None
        if not a.get("filename"):
            rd.problems.append(f"{where} <mesh> has no filename attribute: add one")
        return GeometryElement(
            link,
            name,
            source,
            k,
            "mesh",
            T,
            filename=a.get("filename") or None,
            scale=np.ones(3) if scale is None else scale,
        )
    if shape == "box":
        size = rd.vector(a.get("size"), f"{where} <box size>")
        if size is None or np.any(size <= 0):
            rd.problems.append(
                f"{where} <box> needs size='sx sy sz' with positive lengths in metres"
            )
            return GeometryElement(link, name, source, k, None, T)
        return GeometryElement(link, name, source, k, "box", T, size=size)
    if shape in ("cylinder", "sphere"):
        radius = rd.number(a.get("radius"), f"{where} <{shape} radius>")
        length = (
            rd.number(a.get("length"), f"{where} <cylinder length>") if shape == "cylinder" else 0.0
        )
        if radius is None or radius <= 0 or length is None or length < 0:
            need = "radius and length" if shape == "cylinder" else "radius"
            rd.problems.append(f"{where} <{shape}> needs a positive {need} in metres")
            return GeometryElement(link, name, source, k, None, T)
        return GeometryElement(
            link,
            name,
            source,
            k,
            shape,
            T,
            radius=radius,
            length=length if shape == "cylinder" else None,
        )
    return GeometryElement(link, name, source, k, shape, T)


def _link(rd: _Reader, elem: ET.Element) -> LinkElement:
    name = elem.get("name", "")
    cols = tuple(
        _geometry(rd, name, e, "collision", k) for k, e in enumerate(elem.findall("collision"))
    )
    vis = tuple(_geometry(rd, name, e, "visual", k) for k, e in enumerate(elem.findall("visual")))
    return LinkElement(name, cols, vis)


def _joint(rd: _Reader, elem: ET.Element) -> JointElement:
    name = elem.get("name", "")
    where = f"joint {name!r}"
    rd.origin(elem, where)  # records a non-finite origin; Pinocchio reads the pose itself
    axis_elem = elem.find("axis")
    axis = rd.vector("1 0 0" if axis_elem is None else axis_elem.get("xyz", "1 0 0"),
                     f"{where} <axis xyz>")
    limit = elem.find("limit")
    lower = upper = None
    if limit is not None:
        lower = rd.number(limit.get("lower"), f"{where} <limit lower>")
        upper = rd.number(limit.get("upper"), f"{where} <limit upper>")
    mimic = None
    m = elem.find("mimic")
    if m is not None:
        mult = rd.number(m.get("multiplier", "1"), f"{where} <mimic multiplier>")
        off = rd.number(m.get("offset", "0"), f"{where} <mimic offset>")
        mimic = Mimic(
            m.get("joint", ""), 1.0 if mult is None else mult, 0.0 if off is None else off
        )
    parent, child = elem.find("parent"), elem.find("child")
    return JointElement(
        name,
        elem.get("type", ""),
        "" if parent is None else parent.get("link", ""),
        "" if child is None else child.get("link", ""),
        lower,
        upper,
        mimic,
        axis,
    )


# ------------------------------------------------------------------ isf tags
def _check_attrs(rd: _Reader, elem: ET.Element, known: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(elem.attrib) - set(known))
    if unknown:
        rd.problems.append(
            f"{where} has unknown attribute(s) {', '.join(unknown)}; known: {', '.join(known)}"
        )


def _unit(rd: _Reader, text: str | None, where: str) -> np.ndarray | None:
    v = rd.vector(text, where)
    if v is None:
        return None
    norm = float(np.linalg.norm(v))
    if norm < 1e-12:
        rd.problems.append(f"{where}={text!r} is a zero vector: give a direction such as '0 0 1'")
        return None
    return v / norm


def _contact(rd: _Reader, elem: ET.Element, k: int) -> ContactTag | None:
    a = elem.attrib
    name = a.get("name") or ""
    where = f"<isf:contact name={name!r}>" if name else f"<isf:contact> #{k}"
    _check_attrs(rd, elem, _CONTACT_ATTRS, where)
    if not name or not a.get("link"):
        rd.problems.append(f"{where} needs both a name and a link attribute")
        return None
    source = a.get("source", "collision")
    if source not in ("collision", "visual"):
        rd.problems.append(f"{where} source={source!r} must be 'collision' or 'visual'")
        source = "collision"
    max_angle = rd.number(a.get("max_angle", "0.5"), f"{where} max_angle")
    if max_angle is not None and not 0.0 < max_angle <= math.pi:
        rd.problems.append(f"{where} max_angle={max_angle} must lie in (0, pi] radians")
        max_angle = None
    points_text = a.get("points", "256")
    points = int(points_text) if points_text.strip().isdigit() else 0
    if not 1 <= points <= MAX_POINTS:
        rd.problems.append(
            f"{where} points={points_text!r} must be an integer in [1, {MAX_POINTS}] "
            "(a few hundred suffice)"
        )
        points = 256
    flip_text = a.get("flip", "false").strip().lower()
    if flip_text not in ("true", "false", "1", "0"):
        rd.problems.append(f"{where} flip={a['flip']!r} must be 'true' or 'false'")
    box_min = rd.vector(a.get("box_min"), f"{where} box_min")
    box_max = rd.vector(a.get("box_max"), f"{where} box_max")
    if box_min is not None and box_max is not None and np.any(box_min > box_max):
        rd.problems.append(f"{where} box_min must not exceed box_max on any axis: swap them")
    return ContactTag(
        name=name,
        link=a["link"],
        geometry=a.get("geometry") or None,
        source=source,
        normal=_unit(rd, a.get("normal"), f"{where} normal"),
        max_angle=0.5 if max_angle is None else max_angle,
        box_min=box_min,
        box_max=box_max,
        points=points,
        flip=flip_text in ("true", "1"),
    )


def _tcp_origin(rd: _Reader, text: str | None) -> np.ndarray | None:
    """``tcp_origin="x y z [roll pitch yaw]"`` as a pose (4, 4), or None (absent or wrong)."""
    if text is None:
        return None
    n = len(text.split())
    if n not in (3, 6):
        rd.problems.append(f"<isf:gripper> tcp_origin={text!r} must be 'x y z' (metres) or "
                           "'x y z roll pitch yaw' (radians)")
        return None
    values = rd.vector(text, "<isf:gripper> tcp_origin", n=n)
    if values is None:
        return None
    T = np.eye(4)
    T[:3, 3] = values[:3]
    if n == 6:
        T[:3, :3] = rpy_matrix(values[3:])
    return T


def _gripper(rd: _Reader, elem: ET.Element) -> GripperTag:
    _check_attrs(rd, elem, _GRIPPER_ATTRS, "<isf:gripper>")
    tcp_link = elem.get("tcp_link") or None
    T_link_tcp = _tcp_origin(rd, elem.get("tcp_origin"))
    if tcp_link is None and elem.get("tcp_origin") is not None:
        rd.problems.append("<isf:gripper> tcp_origin needs tcp_link, the link it is given in: "
                           "add tcp_link=\"...\"")
    return GripperTag(
        palm_link=elem.get("palm_link") or None,
        approach=_unit(rd, elem.get("approach"), "<isf:gripper> approach"),
        tcp_link=tcp_link,
        T_link_tcp=None if tcp_link is None else np.eye(4) if T_link_tcp is None else T_link_tcp,
    )


def _initial(rd: _Reader, elem: ET.Element) -> InitialTag | None:
    joint = elem.get("joint") or ""
    where = f"<isf:initial joint={joint!r}>"
    _check_attrs(rd, elem, _INITIAL_ATTRS, where)
    value = rd.number(elem.get("value"), f"{where} value")
    if not joint or elem.get("value") is None:
        rd.problems.append(f"{where} needs a joint and a value attribute (metres or radians)")
    return None if not joint or value is None else InitialTag(joint, value)


def _closing(rd: _Reader, elem: ET.Element) -> ClosingTag | None:
    joint = elem.get("joint") or ""
    where = f"<isf:closing joint={joint!r}>"
    _check_attrs(rd, elem, _CLOSING_ATTRS, where)
    sign = rd.number(elem.get("sign"), f"{where} sign")
    if not joint or sign not in (1.0, -1.0, 0.0):
        rd.problems.append(f"{where} needs a joint and a sign attribute of 1, -1 or 0 (holds)")
        return None
    return ClosingTag(joint, sign)


def _read_isf(rd: _Reader, root: ET.Element, isf_uris: set[str]):
    contacts, initial, grippers, closing = [], [], [], []
    top = set(map(id, root))
    for elem in root.iter():
        uri, _, local = elem.tag[1:].partition("}") if elem.tag.startswith("{") else ("", "", "")
        if uri not in isf_uris:
            continue
        if local not in ("contact", "gripper", "initial", "closing"):
            rd.problems.append(
                f"unknown element isf:{local}; known: isf:contact, isf:gripper, isf:initial, "
                "isf:closing"
            )
            continue
        if id(elem) not in top:
            rd.problems.append(f"<isf:{local}> must be a direct child of <robot>: move it there")
        if local == "contact":
            contacts.append(_contact(rd, elem, len(contacts)))
        elif local == "gripper":
            grippers.append(_gripper(rd, elem))
        elif local == "closing":
            closing.append(_closing(rd, elem))
        else:
            initial.append(_initial(rd, elem))
    contacts = [c for c in contacts if c is not None]
    initial = [t for t in initial if t is not None]
    names = [c.name for c in contacts]
    for dup in sorted({n for n in names if names.count(n) > 1}):
        rd.problems.append(
            f"contact surface name {dup!r} is used more than once: make names unique"
        )
    joints = [t.joint for t in initial]
    for dup in sorted({j for j in joints if joints.count(j) > 1}):
        rd.problems.append(f"joint {dup!r} has more than one <isf:initial>: keep one")
    if len(grippers) > 1:
        rd.problems.append("more than one <isf:gripper> tag: keep one")
    closing = [t for t in closing if t is not None]
    joints = [t.joint for t in closing]
    for dup in sorted({j for j in joints if joints.count(j) > 1}):
        rd.problems.append(f"joint {dup!r} has more than one <isf:closing>: keep one")
    return tuple(contacts), (grippers[0] if grippers else None), tuple(initial), tuple(closing)


# ---------------------------------------------------------------------- API
def _syntax_error(original: str, parsed: str) -> URDFReadError:
    """The syntax error of ``parsed`` (``original`` with prefixes declared on its root tag),
    positioned in ``original``.

    The position comes from a plain parse: ``XMLPullParser`` reports positions past the error.
    """
    try:
        plain = ET.XMLParser()
        plain.feed(parsed)
        plain.close()
    except ET.ParseError as exc:
        line, column = exc.position
        reason = str(exc).rsplit(": line ", 1)[0]
    else:  # the pull parser alone rejects the text
        line = column = None
        reason = "the XML parser rejects it"
    if line is not None and len(parsed) > len(original):
        # map a position behind the inserted declarations back into the original text
        at = next((i for i, (a, b) in enumerate(zip(original, parsed)) if a != b), len(original))
        lines = parsed.split("\n")
        offset = sum(len(x) + 1 for x in lines[: line - 1]) + column
        if offset >= at:
            offset = max(at, offset - (len(parsed) - len(original)))
        line = original.count("\n", 0, offset) + 1
        column = offset - (original.rfind("\n", 0, offset) + 1)
    where = "" if line is None else f": line {line}, column {column}"
    return URDFReadError(
        f"not valid XML ({reason}{where}): fix the file's syntax", line=line, column=column
    )


def _refuse_entities(text: str) -> None:
    """Raise URDFReadError when the text declares XML entities (``<!ENTITY>``).

    Pinocchio's URDF reader does not expand entities while isf's would, so the two would read
    different files; entities also let a small file expand into a huge one or name outside
    files. A URDF has no need of them.
    """
    if "<!ENTITY" not in text:  # the usual file: no second parse
        return
    def refuse(name, *rest) -> None:  # declarations precede the root: nothing is expanded yet
        raise URDFReadError(
            f"the file declares the XML entity {name!r} (<!ENTITY>), and URDF readers do not "
            "expand entities alike: write its text out in place and remove the declaration")

    parser = expat.ParserCreate()
    parser.EntityDeclHandler = refuse
    with contextlib.suppress(expat.ExpatError):  # reported by the main parse, with its position
        parser.Parse(text, True)


def _parse_xml(text: str) -> tuple[ET.Element, dict[str, str], list[str]]:
    original = text
    _refuse_entities(text)
    text, missing = _declare_missing_prefixes(text)
    parser = ET.XMLPullParser(events=("start-ns", "start"))
    root, ns = None, {}
    try:
        parser.feed(text)
        parser.close()
        # the pull parser keeps some errors (an undefined entity) until its events are read
        for event, payload in parser.read_events():
            if event == "start-ns":
                ns.setdefault(payload[0], payload[1])
            elif root is None:
                root = payload
    except ET.ParseError as exc:
        raise _syntax_error(original, text) from exc
    if root is None or root.tag != "robot":
        tag = None if root is None else root.tag
        raise URDFReadError(
            f"not a URDF: the root element is <{tag}>, expected <robot>", root_tag=tag
        )
    return root, ns, missing


def parse_tagged_urdf(text: str) -> TaggedURDF:
    """Read links, joints, geometry elements and isf tags from URDF text.

    Args:
        text: the URDF file's content.

    Returns:
        the parsed :class:`TaggedURDF`; non-fatal problems are in ``problems``.

    Raises:
        URDFReadError: the text is not XML or its root is not ``<robot>``.
    """
    root, ns, missing = _parse_xml(text)
    rd = _Reader()
    if "isf" in missing:
        rd.problems.append(
            f'the isf: prefix is not declared: add xmlns:isf="{ISF_NS}" to the <robot> tag'
        )
    isf_uris = {ISF_NS}
    if ns.get("isf", ISF_NS) != ISF_NS:
        isf_uris.add(ns["isf"])
        rd.problems.append(
            f'xmlns:isf is bound to {ns["isf"]!r}: bind it to "{ISF_NS}" '
            "(version 1 of the convention)"
        )
    links: dict[str, LinkElement] = {}
    for elem in root.findall("link"):
        link = _link(rd, elem)
        if link.name in links:
            rd.problems.append(f"link {link.name!r} is defined twice: rename or remove one")
        links.setdefault(link.name, link)
    joints: dict[str, JointElement] = {}
    for elem in root.findall("joint"):
        joint = _joint(rd, elem)
        if joint.name in joints:
            rd.problems.append(f"joint {joint.name!r} is defined twice: rename or remove one")
        joints.setdefault(joint.name, joint)
        for role in ("parent", "child"):
            if getattr(joint, role) not in links:
                rd.problems.append(
                    f"joint {joint.name!r} names {role} link {getattr(joint, role)!r}, "
                    "which does not exist"
                )
    children = {j.child for j in joints.values()}
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        rd.problems.append(
            "the URDF must have exactly one root link (a link that is no joint's child); "
            f"found {roots}"
        )
    contacts, gripper, initial, closing = _read_isf(rd, root, isf_uris)
    return TaggedURDF(
        robot_name=root.get("name", ""),
        links=links,
        joints=joints,
        root_link=roots[0] if len(roots) == 1 else None,
        contacts=contacts,
        gripper=gripper,
        initial=initial,
        problems=rd.problems,
        root=root,
        closing=closing,
    )
