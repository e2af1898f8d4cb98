"""Build the Pinocchio model of a URDF with its mimic joints honoured.

``pin.buildModelFromXML(text, mimic=True)`` (Pinocchio 4.1) numbers joints in
depth-first order, visiting the child joints of a link in joint-name order, and
fails ("The parent joint of the mimic joint is not in the kinematic tree") when a
mimic joint comes before its leader in that order: a gripper whose mimic joint is
``left_joint`` and leader ``right_joint`` would not load. When that happens the
model is rebuilt from a copy of the file whose joints carry temporary name prefixes
that put every subtree holding a leader first; the original names are then written
back into the model, so only the order of the joints in ``q`` differs from
Pinocchio's own.
"""

from __future__ import annotations

import contextlib
import copy
import logging
import os
import sys
import tempfile
import threading
import xml.etree.ElementTree as ET

import pinocchio as pin

from ..exceptions import ModelBuildError
from .urdf_tags import TaggedURDF

__all__ = ["ModelBuildError", "build_model"]

_PREFIX = "isf{:05d}__"

log = logging.getLogger(__name__)

_STDERR_LOCK = threading.Lock()


@contextlib.contextmanager
def _cxx_stderr_to_log():
    """Catch what C++ code writes to the process's stderr (file descriptor 2) inside the block,
    and log it at debug level: urdfdom prints its complaints there, and they would reach the
    terminal ahead of isf's own one-line message. Python's ``sys.stderr`` is untouched."""
    with _STDERR_LOCK, tempfile.TemporaryFile() as caught:
        with contextlib.suppress(AttributeError, ValueError, OSError):
            sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(caught.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            caught.seek(0)
            text = caught.read().decode("utf-8", "replace").strip()
            if text:
                log.debug("urdfdom: %s", " ".join(text.split()))


def _build(xml: str) -> pin.Model:
    """``pin.buildModelFromXML(xml, mimic=True)`` with urdfdom's stderr lines logged."""
    with _cxx_stderr_to_log():
        return pin.buildModelFromXML(xml, mimic=True)


def _leader_first_ranks(doc: TaggedURDF) -> dict[str, int]:
    """Depth-first rank of every joint, visiting subtrees that hold a mimic leader first."""
    leaders = {j.mimic.joint for j in doc.joints.values() if j.mimic is not None}
    children: dict[str, list] = {}
    for joint in doc.joints.values():
        children.setdefault(joint.parent, []).append(joint)

    holds: dict[str, bool] = {}

    def holds_leader(joint) -> bool:
        if joint.name not in holds:
            holds[joint.name] = False  # guards against cycles in a broken file
            below = children.get(joint.child, [])
            holds[joint.name] = joint.name in leaders or any(holds_leader(j) for j in below)
        return holds[joint.name]

    ranks: dict[str, int] = {}
    seen: set[str] = set()

    def visit(link: str) -> None:
        seen.add(link)
        for joint in sorted(children.get(link, []), key=lambda j: (not holds_leader(j), j.name)):
            if joint.child not in seen:
                ranks[joint.name] = len(ranks)
                visit(joint.child)

    visit(doc.root_link)
    return ranks


def _renamed_xml(doc: TaggedURDF, ranks: dict[str, int]) -> str:
    root = copy.deepcopy(doc.root)
    for elem in list(root):
        if elem.tag.startswith("{"):  # isf:*, drake:*, ... mean nothing to Pinocchio
            root.remove(elem)
    for joint in root.findall("joint"):
        name = joint.get("name", "")
        if name in ranks:
            joint.set("name", _PREFIX.format(ranks[name]) + name)
        mimic = joint.find("mimic")
        if mimic is not None and mimic.get("joint") in ranks:
            mimic.set("joint", _PREFIX.format(ranks[mimic.get("joint")]) + mimic.get("joint"))
    return ET.tostring(root, encoding="unicode")


def _strip_prefixes(model: pin.Model, ranks: dict[str, int]) -> None:
    original = {_PREFIX.format(rank) + name: name for name, rank in ranks.items()}
    for jid in range(model.njoints):
        if model.names[jid] in original:
            model.names[jid] = original[model.names[jid]]
    for frame in model.frames:
        if frame.name in original:
            frame.name = original[frame.name]


def build_model(text: str, doc: TaggedURDF) -> pin.Model:
    """The fixed-base Pinocchio model of a URDF, mimic joints honoured.

    Args:
        text: the URDF file's content.
        doc: the same file parsed by :func:`isf.gripper.urdf_tags.parse_tagged_urdf`.

    Returns:
        the model; ``model.nq`` counts actuated joints only.

    Raises:
        ModelBuildError: Pinocchio rejects the file.
    """
    try:
        return _build(text)
    except (RuntimeError, ValueError) as exc:
        first = exc
    if doc.root is None or doc.root_link is None or "mimic" not in str(first):
        raise ModelBuildError(first, "fix the URDF structure")
    ranks = _leader_first_ranks(doc)
    try:
        model = _build(_renamed_xml(doc, ranks))
    except (RuntimeError, ValueError) as exc:
        raise ModelBuildError(
            exc,
            "every mimic joint must follow its leader in depth-first order; "
            "restructure the joint tree",
        ) from exc
    _strip_prefixes(model, ranks)
    return model
