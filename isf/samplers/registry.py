"""Find samplers by name: the ``isf.samplers`` entry-point group plus run-time registrations.

Built-in and third-party samplers are found the same way. A distribution
declares its samplers in its ``pyproject.toml``::

    [project.entry-points."isf.samplers"]
    normal = "isf_sampler_normal:NormalSampler"

:func:`available_samplers` lists them without importing anything;
:func:`get_sampler` imports one on first use. :func:`register_sampler` adds a
class at run time (it wins over an entry point of the same name) and
:func:`refresh_samplers` re-reads the entry points after a ``pip install``.
"""

from __future__ import annotations

import functools
import importlib.metadata
import inspect
import logging
import re
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

from ..exceptions import ConfigError, PluginLoadError, SamplerNotFound
from .base import Sampler

__all__ = [
    "ENTRY_POINT_GROUP",
    "SamplerInfo",
    "available_samplers",
    "get_sampler",
    "refresh_samplers",
    "register_sampler",
]

logger = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "isf.samplers"
_NAME = re.compile(r"[a-z0-9_]+")
_INSTALL_HINT = (
    f"install a package that declares it in the {ENTRY_POINT_GROUP!r} entry-point group "
    "(e.g. pip install -e plugins/isf-sampler-normal) or call isf.samplers.register_sampler()"
)

#: Samplers added with :func:`register_sampler`, by name.
_registered: dict[str, type[Sampler]] = {}


@dataclass(frozen=True)
class SamplerInfo:
    """Where a sampler comes from.

    Attributes:
        name: public name, used in configs and :func:`get_sampler`.
        value: the object path, ``"module:Class"``.
        distribution: the distribution that declares it, or None for a
            run-time registration.
        version: that distribution's version, or None.
        description: the class's one-line description; only filled when
            listed with ``load=True``.
    """

    name: str
    value: str
    distribution: str | None = None
    version: str | None = None
    description: str | None = None

    @property
    def source(self) -> str:
        """``"dist version"`` or ``"registered at run time"``, for messages."""
        if self.distribution is None:
            return "registered at run time"
        return f"{self.distribution} {self.version}"


def _entry_points() -> Iterable[importlib.metadata.EntryPoint]:
    """Entry points of the ``isf.samplers`` group (the one seam tests replace)."""
    return importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)


@functools.cache
def _discover() -> tuple[dict[str, SamplerInfo], dict[str, Any]]:
    """Read the entry points once: their infos and the entry points themselves, by name."""
    infos: dict[str, SamplerInfo] = {}
    eps: dict[str, Any] = {}
    for ep in _entry_points():
        dist = getattr(ep, "dist", None)
        info = SamplerInfo(
            name=ep.name,
            value=ep.value,
            distribution=None if dist is None else dist.name,
            version=None if dist is None else dist.version,
        )
        if ep.name in infos:
            kept = infos[ep.name]
            warnings.warn(
                f"sampler {ep.name!r} is declared by two distributions, {kept.source} "
                f"({kept.value}) and {info.source} ({info.value}); using the first. "
                "Uninstall one of them to silence this warning.",
                RuntimeWarning,
                stacklevel=3,
            )
            continue
        infos[ep.name] = info
        eps[ep.name] = ep
    return infos, eps


def refresh_samplers() -> None:
    """Forget the cached entry points (call after installing or removing a plugin)."""
    _discover.cache_clear()


def available_samplers(*, load: bool = False) -> dict[str, SamplerInfo]:
    """Every sampler that :func:`get_sampler` can build, sorted by name.

    Args:
        load: also import each sampler to read its description. A plugin that
            fails to load is then left out with a RuntimeWarning.

    Returns:
        ``{name: SamplerInfo}``, sorted by name.
    """
    infos = dict(_discover()[0])
    for name, cls in _registered.items():
        infos[name] = SamplerInfo(name=name, value=f"{cls.__module__}:{cls.__qualname__}")
    if load:
        for name in list(infos):
            try:
                cls = _load_class(name)
            except PluginLoadError as err:
                warnings.warn(f"skipping sampler {name!r}: {err}", RuntimeWarning, stacklevel=2)
                del infos[name]
                continue
            infos[name] = replace(infos[name], description=cls.description)
    return dict(sorted(infos.items()))


def register_sampler(name: str, cls: type[Sampler]) -> None:
    """Make ``cls`` available as ``name`` for this process; it wins over entry points.

    Args:
        name: public name, ``[a-z0-9_]+``.
        cls: a :class:`Sampler` subclass.

    Raises:
        ConfigError: for a malformed name.
        PluginLoadError: when ``cls`` is not a Sampler subclass.
    """
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ConfigError(f"sampler name {name!r} is invalid; use lowercase [a-z0-9_]+")
    if not (isinstance(cls, type) and issubclass(cls, Sampler)):
        raise PluginLoadError(
            f"cannot register {cls!r} as sampler {name!r}: it is not a subclass of "
            "isf.samplers.Sampler; derive it from Sampler", name=name
        )
    if name in _registered and _registered[name] is not cls:
        logger.info("sampler %r re-registered: %r replaces %r", name, cls, _registered[name])
    _registered[name] = cls


def _load_class(name: str) -> type[Sampler]:
    """The Sampler class registered as ``name``, importing its plugin if needed."""
    if name in _registered:
        return _registered[name]
    infos, eps = _discover()
    if name not in eps:
        installed = ", ".join(available_samplers()) or "none"
        if not any(info.distribution == "isf" for info in infos.values()):
            installed += " (isf's own built-ins are missing: install isf, e.g. pip install -e .)"
        raise SamplerNotFound(f"no sampler named {name!r}; installed: {installed}; {_INSTALL_HINT}",
                              name=name, known=available_samplers())
    info = infos[name]
    try:
        obj = eps[name].load()
    except Exception as err:  # any import-time failure of third-party code
        raise PluginLoadError(
            f"sampler {name!r} ({info.value} from {info.source}) failed to load: "
            f"{type(err).__name__}: {err}; fix or uninstall {info.distribution or 'it'}", name=name
        ) from err
    if not (isinstance(obj, type) and issubclass(obj, Sampler)):
        raise PluginLoadError(
            f"sampler {name!r} ({info.value} from {info.source}) is {obj!r}, not a subclass of "
            "isf.samplers.Sampler; point the entry point at a Sampler subclass", name=name
        )
    if obj.name != name:
        warnings.warn(
            f"sampler entry point {name!r} ({info.source}) loads a class whose name is "
            f"{obj.name!r}; make the entry-point name and {obj.__qualname__}.name agree",
            RuntimeWarning,
            stacklevel=3,
        )
    return obj


def _init_parameters(cls: type) -> list[str]:
    """Names of the keyword parameters ``cls(...)`` accepts."""
    try:
        params = inspect.signature(cls).parameters.values()
    except (TypeError, ValueError):
        return []
    return [p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)]


def get_sampler(sampler: str | type[Sampler] | Sampler, /, **params: Any) -> Sampler:
    """A ready-to-use sampler from a name, a class or an instance.

    Args:
        sampler: a registered name (see :func:`available_samplers`), a
            :class:`Sampler` subclass, or an instance (returned as is).
        **params: keyword parameters of the sampler's constructor.

    Returns:
        a new sampler instance (or the instance passed in).

    Raises:
        SamplerNotFound: no sampler has that name.
        PluginLoadError: the plugin failed to import or is not a Sampler subclass.
        ConfigError: a parameter is unknown or out of range, or parameters were
            given together with an instance.
    """
    if isinstance(sampler, Sampler):
        if params:
            raise ConfigError(
                f"parameters {sorted(params)} were given with a ready {type(sampler).__name__} "
                "instance; pass the name or the class instead, or configure the instance"
            )
        return sampler
    if isinstance(sampler, str):
        cls = _load_class(sampler)
    elif isinstance(sampler, type) and issubclass(sampler, Sampler):
        cls = sampler
    else:
        names = ", ".join(available_samplers()) or "none installed"
        raise ConfigError(
            f"cannot make a sampler from {sampler!r}; pass a name ({names}), "
            "a Sampler subclass or a Sampler instance"
        )
    try:
        inspect.signature(cls).bind(**params)
    except TypeError as err:
        accepted = ", ".join(_init_parameters(cls)) or "none"
        raise ConfigError(
            f"sampler {cls.name or cls.__name__!r}: {err}; accepted parameters: {accepted}"
        ) from err
    return cls(**params)
