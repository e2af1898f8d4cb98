"""Write the tagged copy of a stock gripper URDF (:func:`tag_urdf`) and validate it.

The shortest path from a vendor URDF (meshes untouched) to a gripper isf can plan with::

    from isf.registration import suggest_approach, suggest_contacts, tag_urdf

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
"""

from __future__ import annotations

import logging
import os
import re
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from xml.sax.saxutils import escape, unescape

import numpy as np

from ..exceptions import MeshNotFoundError, RegistrationError
from ..gripper.loading import inspect_gripper
from ..gripper.mesh_paths import PackageDirs, mesh_path_candidates, resolve_mesh_path
from ..gripper.urdf_tags import ISF_NS
from ..output_files import check_output_path, write_atomically
from ._urdf_source import initial_tags, parse_urdf, read_urdf
from .preview import TagPreview, preview_surfaces
from .spec import _ATTR_FLOAT, ContactSpec, _element, _format_vector, _vector
from .suggestion import SuggestedTCP, suggest_closing

__all__ = ["tag_urdf"]

log = logging.getLogger(__name__)

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


def _gripper_element(palm_link: str | None, approach, tcp=None) -> str | None:
    attrs = []
    if palm_link is not None:
        if not isinstance(palm_link, str) or not palm_link:
            raise RegistrationError(f"palm_link={palm_link!r} must be a link name")
        attrs.append(("palm_link", palm_link))
    approach = _vector(approach, "approach", direction=True)
    if approach is not None:
        unit = np.asarray(approach) / np.linalg.norm(approach)
        attrs.append(("approach", _format_vector(unit)))
    if tcp is not None:
        origin = _vector(getattr(tcp, "origin", None), "tcp origin")
        if not isinstance(getattr(tcp, "link", None), str) or not tcp.link or origin is None:
            raise RegistrationError(f"tcp={tcp!r} must be a SuggestedTCP(link, (x, y, z)), e.g. "
                                    "suggest_tcp(urdf)")
        attrs += [("tcp_link", tcp.link), ("tcp_origin", _format_vector(origin))]
    return _element("gripper", attrs) if attrs else None


def _closing_elements(closing: Mapping[str, float]) -> list[str]:
    """``<isf:closing joint sign>`` lines, one per joint."""
    return [_element("closing", [("joint", joint), ("sign", f"{int(np.sign(sign))}")])
            for joint, sign in closing.items()]


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
    tcp: SuggestedTCP | None = None,
    closing: Mapping[str, float] | str | None = None,
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
        tcp: optional tool-centre point (``<isf:gripper tcp_link tcp_origin>``), e.g. from
            :func:`isf.registration.suggest_tcp`; its link must be fixed to the root link.
        closing: optional ``<isf:closing>`` signs ``{joint: +1 or -1}``, or ``"suggest"`` for
            :func:`isf.registration.suggest_closing`'s (from the contact normals, once the
            copy loads).

    Returns:
        the :class:`TagPreview`; ``preview.ok`` is True when the copy loads.

    Raises:
        RegistrationError: bad arguments, an unreadable source, an existing ``isf:*`` tag
            (without ``replace_tags``), or ``out_path`` naming the source.
        OutputFileError: ``out_path`` is a folder, a symbolic link or a FIFO, or cannot be
            written (checked before anything is written).
    """
    t0 = time.perf_counter()
    src, text = read_urdf(urdf_path)
    dst = Path(out_path).expanduser().absolute()
    if dst.parent.is_dir():  # a missing folder is created below
        check_output_path(dst, "tagged URDF")
    if dst.exists() and os.path.samefile(dst, src):
        raise RegistrationError(
            f"out_path {dst} is the source file; isf never edits the vendor file: "
            "write the copy under another name",
            source=src,
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
    if isinstance(closing, str) and closing != "suggest":
        raise RegistrationError(f"closing={closing!r}: give {{joint: sign}} or 'suggest'")
    gripper = _gripper_element(palm_link, approach, tcp)
    new_initial = initial_tags(initial)

    doc = parse_urdf(text, src)
    if doc.contacts or doc.gripper or doc.initial or re.search(r"<isf:", _COMMENT.sub("", text)):
        if not replace_tags:
            raise RegistrationError(
                f"{src} already has isf:* tags: pass replace_tags=True (CLI: --replace) to "
                "drop them, or tag the untagged vendor file",
                source=src,
            )
        text = _remove_isf_elements(text)
    new, added = _declare_namespace(text)
    rewrites = _mesh_rewrites(new, src.parent, dst.parent, package_dirs)
    new = _apply_rewrites(new, rewrites)
    elements = [gripper] if gripper else []
    elements += [c.to_xml() for c in contacts]
    elements += [
        _element("initial", [("joint", t.joint), ("value", _ATTR_FLOAT.format(t.value))])
        for t in new_initial
    ]
    if isinstance(closing, Mapping):
        elements += _closing_elements(closing)
    with_tags = _insert_elements(new, elements)
    dst.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(dst, with_tags.encode("utf-8"), "tagged URDF")
    if closing == "suggest" and inspect_gripper(dst).ok:
        suggested = _closing_elements(suggest_closing(dst))
        elements += suggested
        with_tags = _insert_elements(new, elements)
        write_atomically(dst, with_tags.encode("utf-8"), "tagged URDF")
    new = with_tags
    t1 = time.perf_counter()
    log.info(
        "wrote %s (%d isf elements, %d mesh paths made absolute)",
        dst,
        len(elements),
        len(rewrites),
    )

    report = inspect_gripper(dst)
    surfaces, q_initial = preview_surfaces(new, dst.parent, report)
    return TagPreview(
        source_path=src,
        urdf_path=dst,
        surfaces=surfaces,
        report=report,
        rewritten_meshes=rewrites,
        namespace_added=added,
        q_initial=q_initial,
        tag_time=t1 - t0,
        validation_time=time.perf_counter() - t1,
    )
