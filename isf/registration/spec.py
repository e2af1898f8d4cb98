"""One ``<isf:contact>`` to write: :class:`ContactSpec`, its checks, parsing ``--contact`` words
and its XML element."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

import numpy as np

from ..exceptions import RegistrationError
from ..gripper.urdf_tags import MAX_POINTS

__all__ = ["ContactSpec"]

_ATTR_FLOAT = "{:.6g}"  # micrometres for lengths up to 1 m, 1e-6 for unit vectors


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


def _format_vector(v) -> str:
    # round-off below 1e-12 becomes 0 so the file reads "0 0 1", not "1.49e-14 0 1"
    return " ".join(_ATTR_FLOAT.format(0.0 if abs(x) < 1e-12 else x) for x in v)


def _element(local: str, attrs: Sequence[tuple[str, str]]) -> str:
    """The empty element ``<isf:local k="v" .../>`` with XML-quoted attribute values."""
    return f"<isf:{local} " + " ".join(f"{k}={quoteattr(v)}" for k, v in attrs) + "/>"


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
        if (
            self.box_min is not None
            and self.box_max is not None
            and any(lo > hi for lo, hi in zip(self.box_min, self.box_max))
        ):
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
        fields = set(cls.__dataclass_fields__)
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
