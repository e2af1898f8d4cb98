"""The URDF to register, read and placed at its initial configuration, and the triangle
measures the suggestions and the preview share.

Shared by ``tag_urdf`` and the suggestions; a file that cannot be read becomes a
:class:`~isf.exceptions.RegistrationError` naming it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..exceptions import RegistrationError, URDFReadError
from ..gripper.loading import initial_configuration
from ..gripper.urdf_model import build_model
from ..gripper.urdf_tags import InitialTag, TaggedURDF, parse_tagged_urdf


def read_urdf(urdf_path: str | Path) -> tuple[Path, str]:
    """The resolved path and UTF-8 text of a URDF file."""
    path = Path(urdf_path).expanduser()
    if not path.is_file():
        raise RegistrationError(
            f"{str(urdf_path)!r} is not a file: give the path of a .urdf file", source=path
        )
    try:
        return path.resolve(), path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RegistrationError(
            f"{path} is not UTF-8 text ({exc}): convert the file to UTF-8", source=path
        ) from exc


def parse_urdf(text: str, path: Path) -> TaggedURDF:
    """:func:`~isf.gripper.urdf_tags.parse_tagged_urdf` with the file named in the error."""
    try:
        return parse_tagged_urdf(text)
    except URDFReadError as exc:
        raise RegistrationError(f"{path}: {exc}", source=path) from exc


def initial_tags(initial: Mapping[str, float] | None) -> tuple[InitialTag, ...]:
    """``<isf:initial>`` tags from a ``{joint: value}`` map (metres or radians)."""
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
class Posed:
    """A URDF's model at its initial configuration.

    Attributes:
        doc: the parsed URDF with the initial values used.
        model: its Pinocchio model.
        q: the initial joint vector, (model.nq,), metres or radians.
        poses: ``T_root_link`` of every link, (4, 4) each.
    """

    doc: TaggedURDF
    model: pin.Model
    q: np.ndarray
    poses: dict[str, np.ndarray]

    def joint_values(self) -> dict[str, float]:
        """The initial value of every actuated joint by name."""
        model = self.model
        return {
            model.names[j]: float(self.q[model.joints[j].idx_q])
            for j in range(1, model.njoints)
            if model.joints[j].nq > 0
        }


def pose_urdf(text: str, doc: TaggedURDF, initial: tuple[InitialTag, ...]) -> Posed:
    """Build the model and place every link at the initial configuration; ``initial``
    overrides the file's own ``<isf:initial>`` tags.

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
    return Posed(doc_q, model, q, poses)


def face_normals(tris: np.ndarray) -> np.ndarray:
    """Unit normals of triangles (F, 3, 3) by their winding, (F, 3)."""
    cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    return cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-300)[:, None]


def face_areas(tris: np.ndarray) -> np.ndarray:
    """Areas of triangles (F, 3, 3), (F,), in the square of their length unit."""
    return 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
