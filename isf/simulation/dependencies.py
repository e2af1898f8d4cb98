"""The optional packages of the physics test (the extra ``isf[sim]``)."""

from __future__ import annotations

import importlib
import importlib.util

from ..exceptions import InvalidInputError

__all__ = ["SIM_PACKAGES", "require_simulator"]

#: Modules the physics test needs, with the package that installs each.
SIM_PACKAGES = {"mujoco": "mujoco", "coacd": "coacd", "yourdfpy": "yourdfpy", "trimesh": "trimesh"}


def require_simulator() -> None:
    """Import the physics test's packages, or raise one line that names the fix.

    Raises:
        InvalidInputError: one of :data:`SIM_PACKAGES` is not installed.
    """
    for module, package in SIM_PACKAGES.items():
        try:  # CoACD is only looked up: it runs in a child process (isf.simulation.object_body)
            found = module == "coacd" and importlib.util.find_spec(module) is not None
            if not found:
                importlib.import_module(module)
        except ImportError:
            raise InvalidInputError(f"isf validate needs {package}, which is not installed: "
                                    "pip install 'isf[sim]'") from None
