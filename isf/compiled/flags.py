"""numba's compiler flags compared without rebuilding every option: :func:`install`.

numba's type inference looks each overloaded call of a kernel (``np.zeros``, ``min``, an
array method, ...) up in a cache keyed by the compiler's flags, a ``TargetConfig``. Hashing or
comparing flags builds the dict of all their options (``TargetConfig.values``) through one
property call per option: about 6 us, some 400 000 times while isf's kernels compile, a few
seconds of the first run's compiling (docs/benchmarks.md, "First run").

:func:`install` gives ``TargetConfig`` a ``values`` that returns the same dict (same keys,
order and values) from each class's defaults, gathered once, updated with the options set.
It changes nothing when numba's internals are not the ones it knows (it then leaves numba
as it is), and nothing that numba compiles or caches.
"""

from __future__ import annotations

__all__ = ["install"]

_defaults: dict[type, dict] = {}
"""Each ``TargetConfig`` class's options and their defaults, in the class's option order."""


def _values(config) -> dict:
    """``TargetConfig.values``: every option of ``config`` (the set ones, else their default)."""
    defaults = _defaults.get(type(config))
    if defaults is None:
        defaults = _defaults[type(config)] = {name: option.default
                                              for name, option in type(config).options.items()}
    values = dict(defaults)
    values.update(config._values)
    return values


def install() -> bool:
    """Make numba's flags quick to hash and compare (see the module docstring); True when
    installed (also when it already was), False when numba's ``TargetConfig`` is not as known."""
    try:
        from numba.core.compiler import Flags
        from numba.core.targetconfig import TargetConfig
    except ImportError:
        return False
    if TargetConfig.values is _values:
        return True
    original = TargetConfig.values
    try:
        probe = Flags()
        probe.nrt = True
        known = (isinstance(getattr(probe, "_values", None), dict)
                 and _values(probe) == original(probe)
                 and list(_values(probe)) == list(original(probe)))
    except Exception:  # an attribute this module relies on is gone
        known = False
    if known:
        TargetConfig.values = _values
    return known
