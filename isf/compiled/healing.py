"""numba functions whose disk cache heals: :func:`cached_njit`.

numba caches each compiled function in an index file (``<name>.nbi``) and one data file per
signature (``<name>.<n>.nbc``), and unpickles them at the first call of each process. A file
cut short (a full disk, an interrupted copy of the cache, a file system that lost a write) makes
that unpickling raise, at every later call, in every later process.

:class:`HealingCache` is numba's own cache with one difference: an entry that cannot be
loaded is dropped (the function's index and data files deleted), a one-line warning says so on
the ``isf.compiled`` logger, and numba compiles the function afresh and saves it again. A
cache that cannot be written (a full or read-only disk) gives a warning instead of an error:
the function then compiles again in the next process.

Importing this module first brings the cache up to date with the sources
(:func:`isf.compiled.cache.refresh_installed`): every kernel of isf is made here, so no kernel
can load before that.
"""

from __future__ import annotations

import contextlib
import glob
import logging
from pathlib import Path

from numba import njit

from .cache import refresh_installed
from .flags import install as install_quick_flags

__all__ = ["cached_njit", "logger"]

logger = logging.getLogger("isf.compiled")
"""Where a dropped or unsaved cache entry is reported (level WARNING, one line)."""

refresh_installed()  # before any kernel of isf exists: drop cached kernels whose sources changed
install_quick_flags()  # numba's flags hashed and compared in a tenth of the time: compiles faster

try:
    from numba.core.caching import FunctionCache
except ImportError:  # numba's internals moved: its own cache, without healing
    FunctionCache = None


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split())
    return f"{type(error).__name__}: {text[:200]}" if text else type(error).__name__


if FunctionCache is not None:

    class HealingCache(FunctionCache):
        """numba's cache of one function, dropping entries it cannot load (see the module
        docstring)."""

        def load_overload(self, sig, target_context):
            try:
                return super().load_overload(sig, target_context)
            except Exception as error:  # an unreadable index or data file: compile afresh
                self.drop()
                logger.warning("dropped an unreadable entry of isf's compiled-kernel cache, %s (%s): "
                               "compiling it again", self._py_func.__qualname__, _one_line(error))
                return None

        def save_overload(self, sig, data):
            try:
                super().save_overload(sig, data)
            except Exception:  # an unreadable index: start the function's entries afresh
                self.drop()
                try:
                    super().save_overload(sig, data)
                except Exception as error:  # a full or read-only disk: run uncached
                    logger.warning("could not save isf's compiled kernel %s in its cache (%s): it "
                                   "compiles again in the next run", self._py_func.__qualname__,
                                   _one_line(error))

        def drop(self) -> None:
            """Delete this function's index and data files (every signature)."""
            base = glob.escape(self._impl.filename_base)
            folder = Path(self._cache_path)
            for path in [*folder.glob(f"{base}.nbi"), *folder.glob(f"{base}.*.nbc")]:
                with contextlib.suppress(OSError):  # a read-only folder: the save says so
                    path.unlink(missing_ok=True)


def cached_njit(function, **options):
    """``numba.njit(**options)(function)``, cached on disk by :class:`HealingCache` (numba's
    own ``cache=True`` where its internals differ from those this module knows)."""
    if FunctionCache is None:
        return njit(cache=True, **options)(function)
    dispatcher = njit(**options)(function)
    try:
        dispatcher._cache = HealingCache(dispatcher.py_func)
    except Exception:  # numba's internals moved, or no folder to cache in: numba's own handling
        dispatcher.enable_caching()
    return dispatcher
