"""The error and warning hierarchy of isf.

Every error a user can cause derives from :class:`ISFError` and carries a one-line message that
names the problem and the fix, plus the data behind the message as attributes (the joint and its
limits, the mesh filename and the paths tried, the unknown name and the known ones), so that a
program can react without parsing text. Programming errors inside isf are left to Python's own
exceptions.

An error whose message has one form builds it from its data (``MeshNotFoundError(filename,
tried)``); an error raised in several situations takes the message first and its data as keyword
arguments (``UnknownAssetError(message, name=..., known=...)``). Every error pickles with its
message and attributes (``ISFError.__reduce__``), so it crosses process boundaries intact.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

__all__ = [
    "AssetFetchError",
    "ConfigError",
    "GeometryLoadError",
    "GripperDescriptionError",
    "ISFError",
    "ISFWarning",
    "InvalidInputError",
    "JointLimitError",
    "JointLimitViolation",
    "MeshNotFoundError",
    "ModelBuildError",
    "ObjectLoadError",
    "ObjectSizeWarning",
    "OutputFileError",
    "PluginLoadError",
    "QPStepError",
    "RegistrationError",
    "SamplerNotFound",
    "SurfaceSelectionError",
    "URDFReadError",
    "UnknownAssetError",
    "YCBNotFoundError",
]


def _restore(cls: type, args: tuple, state: dict[str, Any]) -> ISFError:
    """Rebuild a pickled :class:`ISFError` without calling its ``__init__``."""
    error = cls.__new__(cls, *args)
    error.args = args
    error.__dict__.update(state)
    return error


class ISFError(Exception):
    """Base class of every error raised by isf for bad input or a failed step."""

    def __reduce__(self):
        # BaseException pickles as cls(*self.args), which fails for an __init__ whose
        # parameters are the error's data rather than its message
        return _restore, (type(self), self.args, dict(self.__dict__))


# ------------------------------------------------------------------ input and configuration
class ConfigError(ISFError, ValueError):
    """A configuration value is out of its allowed range."""


class InvalidInputError(ISFError, ValueError):
    """An argument has the wrong shape, is not finite, or is out of range."""


class JointLimitViolation(NamedTuple):
    """One joint value outside its limits (metres or radians)."""

    joint: str
    value: float
    lower: float
    upper: float


class JointLimitError(InvalidInputError):
    """Joint values lie outside their limits; one error reports every joint that does.

    Attributes:
        violations: one :class:`JointLimitViolation` per offending joint, in joint order.
        joint, value, lower, upper: those of the first violation (the only one when a single
            joint is out of its limits).
    """

    def __init__(self, violations: Sequence[JointLimitViolation], what: str = "joints"):
        self.violations = tuple(JointLimitViolation(*v) for v in violations)
        if not self.violations:
            raise ValueError("JointLimitError needs at least one violation")
        self.what = what
        listed = ", ".join(
            f"{v.joint}={v.value:g} not in [{v.lower:g}, {v.upper:g}]" for v in self.violations
        )
        super().__init__(f"{what} outside their limits: {listed}")

    @property
    def joint(self) -> str:
        return self.violations[0].joint

    @property
    def value(self) -> float:
        return self.violations[0].value

    @property
    def lower(self) -> float:
        return self.violations[0].lower

    @property
    def upper(self) -> float:
        return self.violations[0].upper


# ------------------------------------------------------------------ grippers
class GripperDescriptionError(ISFError):
    """A gripper URDF is unusable; ``errors`` lists every problem found.

    Attributes:
        errors: one message per problem, each naming the fix.
        source: the URDF path or bundled name that was loaded.
    """

    def __init__(self, source: str, errors: list[str]):
        self.source = str(source)
        self.errors = list(errors)
        n = len(self.errors)
        head = f"{self.source}: {n} problem{'s' if n != 1 else ''}"
        super().__init__(head + ": " + "; ".join(self.errors))


class URDFReadError(ISFError, ValueError):
    """The text is not XML, or its root element is not ``<robot>``.

    Attributes:
        detail: what is wrong and the fix (the message).
        line, column: position of the XML syntax error (1-based line, 0-based column), or None.
        root_tag: the root element's tag when it is not ``<robot>`` (None: no root element).
    """

    def __init__(
        self,
        detail: str,
        *,
        line: int | None = None,
        column: int | None = None,
        root_tag: str | None = None,
    ):
        self.detail = detail
        self.line, self.column, self.root_tag = line, column, root_tag
        super().__init__(detail)


class MeshNotFoundError(ISFError):
    """A URDF mesh filename matches no file.

    Attributes:
        filename: the filename as written in the URDF.
        tried: every path that was checked, in order.
        link: the link whose geometry names the mesh, or None when not known.
    """

    def __init__(self, filename: str, tried: Sequence[Path], link: str | None = None):
        self.filename = filename
        self.tried = list(tried)
        self.link = link
        shown = ", ".join(str(p) for p in self.tried) or "nothing"
        super().__init__(
            f"mesh {filename!r} not found (tried {shown}); fix the path or pass "
            f"package_dirs={{'<pkg>': '/path/to/pkg'}} for package:// paths"
        )


class ModelBuildError(ISFError, ValueError):
    """Pinocchio cannot build a kinematic model from the URDF.

    Attributes:
        reason: Pinocchio's own message.
        fix: what to change in the URDF.
    """

    def __init__(self, reason: str, fix: str):
        self.reason, self.fix = str(reason), fix
        super().__init__(f"Pinocchio cannot build the kinematic model ({self.reason}): {fix}")


class GeometryLoadError(ISFError, ValueError):
    """A URDF geometry element cannot be turned into a triangle mesh.

    Attributes:
        path: the mesh file that could not be used, or None for a primitive shape.
        shape: the geometry's tag (``"mesh"``, ``"box"``, ..., or an unsupported one).
    """

    def __init__(self, message: str, *, path: Path | None = None, shape: str | None = None):
        self.path, self.shape = path, shape
        super().__init__(message)


class SurfaceSelectionError(ISFError, ValueError):
    """An ``<isf:contact>`` tag selects no usable geometry or no face.

    Attributes:
        contact: the contact tag's name.
        link: the link the tag names.
    """

    def __init__(self, message: str, *, contact: str, link: str):
        self.contact, self.link = contact, link
        super().__init__(message)


class RegistrationError(ISFError, ValueError):
    """Bad input to ``isf.registration.tag_urdf`` or ``isf.registration.suggest_contacts`` (the
    message names the fix).

    Attributes:
        source: the URDF file concerned, or None when the error is about an argument.
    """

    def __init__(self, message: str, *, source: Path | None = None):
        self.source = source
        super().__init__(message)


# ------------------------------------------------------------------ objects and plugins
class ObjectLoadError(ISFError, ValueError):
    """An object mesh or point cloud cannot be read or is unusable.

    Attributes:
        source: the file or object spec that was loaded, or None when not known.
    """

    def __init__(self, message: str, *, source: str | Path | None = None):
        self.source = source
        super().__init__(message)


class SamplerNotFound(ISFError, LookupError):
    """No installed sampler has the requested name.

    Attributes:
        name: the requested sampler name, or None when not given.
        known: the installed sampler names.
    """

    def __init__(self, message: str, *, name: str | None = None, known: Sequence[str] = ()):
        self.name, self.known = name, list(known)
        super().__init__(message)


class PluginLoadError(ISFError):
    """A sampler plugin's entry point failed to load or is not a Sampler.

    Attributes:
        name: the sampler name of the entry point or registration, or None when not given.
    """

    def __init__(self, message: str, *, name: str | None = None):
        self.name = name
        super().__init__(message)


# ------------------------------------------------------------------ output files
class OutputFileError(ISFError):
    """An output file cannot be written where it was asked for (a folder, a symbolic link, a
    FIFO or device, a folder that does not exist or cannot be written, a full disk).

    Attributes:
        path: the output file concerned.
    """

    def __init__(self, message: str, *, path: str | Path):
        self.path = Path(path)
        super().__init__(message)


# ------------------------------------------------------------------ fetched assets
class AssetFetchError(ISFError):
    """A pinned wheel could not be downloaded or did not hold the expected files.

    Attributes:
        package: the pinned requirement concerned (``"pybullet==3.2.7"``), or None.
        path: the cached file or folder concerned, or None.
    """

    def __init__(
        self, message: str, *, package: str | None = None, path: Path | None = None
    ):
        self.package, self.path = package, path
        super().__init__(message)


class YCBNotFoundError(AssetFetchError):
    """The local YCB folder is absent (YCB meshes are never downloaded).

    Attributes:
        searched: the folders that were checked, in order.
    """

    def __init__(self, message: str, *, searched: Sequence[Path] = ()):
        self.searched = list(searched)
        super().__init__(message)


class UnknownAssetError(ISFError, LookupError):
    """The requested gripper, object or object group name does not exist.

    Attributes:
        name: the requested name (a list when several package names were asked for).
        known: the names that exist.
    """

    def __init__(self, message: str, *, name: str | list[str], known: Sequence[str]):
        self.name, self.known = name, list(known)
        super().__init__(message)


# ------------------------------------------------------------------ numerics
class QPStepError(ISFError):
    """The finger-step QP could not be solved.

    Attributes:
        problem: the QP data (P, q, lb, ub) that failed.
        status: the solver's status string.
    """

    def __init__(self, problem, status: str):
        self.problem = problem
        self.status = status
        super().__init__(f"finger-step QP failed with OSQP status {status!r}")


class ISFWarning(UserWarning):
    """Base class of isf's warnings."""


class ObjectSizeWarning(ISFWarning):
    """The object is far outside what the gripper can span: smaller than its smallest opening or
    larger than its largest in every direction (often a file in millimetres read as metres)."""
