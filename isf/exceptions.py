"""The error and warning hierarchy of isf.

Every error a user can cause derives from :class:`ISFError` and carries a
message that names the problem and the fix. Programming errors inside isf are
left to Python's own exceptions.
"""

from __future__ import annotations

__all__ = [
    "ConfigError",
    "GripperDescriptionError",
    "ISFError",
    "ISFWarning",
    "InvalidInputError",
    "ObjectLoadError",
    "PluginLoadError",
    "QPStepError",
    "SamplerNotFound",
]


class ISFError(Exception):
    """Base class of every error raised by isf for bad input or a failed step."""


class ConfigError(ISFError, ValueError):
    """A configuration value is out of its allowed range."""


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


class InvalidInputError(ISFError, ValueError):
    """An argument has the wrong shape, is not finite, or is out of range."""


class ObjectLoadError(ISFError, ValueError):
    """An object mesh or point cloud cannot be read or is unusable."""


class SamplerNotFound(ISFError, LookupError):
    """No installed sampler has the requested name."""


class PluginLoadError(ISFError):
    """A sampler plugin's entry point failed to load or is not a Sampler."""


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
