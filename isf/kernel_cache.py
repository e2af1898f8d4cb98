"""numba's disk cache of isf's kernels, kept consistent with their sources.

numba stores each compiled kernel with a stamp of the file that defines it. But a kernel's
machine code also holds the code of the kernels it calls, which may be defined in other
modules, and the values of the module constants it reads: after an edit of ``box_qp.py``
alone, the cached ``finger_step.bounded_steps`` would go on running the old active set.

So when isf is imported, before any kernel is loaded, :func:`refresh` gives each module a
digest of its source and of the sources of every isf module it imports, directly or not, and
deletes the cached kernels of each module whose digest differs from the one recorded beside
the cache at the last import; those kernels compile afresh on first use. An installed
release never changes its sources, so this acts only after an upgrade (when numba recompiles
anyway) or after an edit of a checkout.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

__all__ = ["module_digests", "refresh", "refresh_installed"]

RECORD = "isf-kernel-sources.json"
"""The file beside the cached kernels that records each module's digest."""

_PACKAGE = Path(__file__).resolve().parent
_IMPORT_MODULE = re.compile(r"^\s*from\s+(?:\.|isf\.)(\w+)[\w.]*\s+import\b", re.MULTILINE)
_IMPORT_NAMES = re.compile(r"^\s*from\s+(?:\.|isf)\s+import\s+(\([^)]*\)|[^\n]*)", re.MULTILINE)
_IMPORT_PLAIN = re.compile(r"^\s*import\s+isf\.(\w+)", re.MULTILINE)


def _imports(source: str, modules: set[str]) -> set[str]:
    """The package's modules (of ``modules``) that ``source`` imports."""
    found = set(_IMPORT_MODULE.findall(source)) | set(_IMPORT_PLAIN.findall(source))
    for names in _IMPORT_NAMES.findall(source):
        found.update(name.split()[0] for name in names.strip("()").split(",") if name.split())
    return found & modules


def module_digests(package: Path = _PACKAGE) -> dict[str, str]:
    """For each module of ``package`` (its top-level ``*.py`` files, by name): a sha256 of its
    source and of the sources of every module of the package it imports, directly or not."""
    sources = {path.stem: path.read_bytes() for path in sorted(package.glob("*.py"))}
    names = set(sources)
    direct = {name: _imports(text.decode("utf-8", "replace"), names) for name, text in sources.items()}
    own = {name: hashlib.sha256(text).hexdigest() for name, text in sources.items()}
    digests = {}
    for name in sources:
        closure, todo = {name}, [name]
        while todo:
            for imported in direct[todo.pop()] - closure:
                closure.add(imported)
                todo.append(imported)
        listing = "".join(f"{member} {own[member]}\n" for member in sorted(closure))
        digests[name] = hashlib.sha256(listing.encode()).hexdigest()
    return digests


def refresh(cache: Path, digests: dict[str, str]) -> list[str]:
    """Delete from the folder ``cache`` the cached kernels (``<module>.*.nbi`` and ``.nbc``) of
    each module whose digest in ``digests`` differs from the one recorded there, then record
    ``digests``. Returns the modules whose kernels were deleted. A folder that cannot be read
    or written is left as it is (numba then does not cache there either)."""
    record = cache / RECORD
    try:
        recorded = json.loads(record.read_text())
    except (OSError, ValueError):
        recorded = {}
    if recorded == digests:
        return []
    stale = sorted(name for name, digest in digests.items() if recorded.get(name) != digest)
    try:
        for name in stale:
            for path in [*cache.glob(f"{name}.*.nbi"), *cache.glob(f"{name}.*.nbc")]:
                path.unlink(missing_ok=True)
        cache.mkdir(parents=True, exist_ok=True)
        record.write_text(json.dumps(digests, indent=0, sort_keys=True))
    except OSError:
        return []
    return stale


def refresh_installed() -> list[str]:
    """:func:`refresh` for this installation: the folder where numba caches isf's kernels (as
    numba locates it for :func:`isf.kdtree.k_nearest`) and the digests of isf's sources."""
    from . import kdtree

    try:
        cache = Path(kdtree.k_nearest._cache._cache_path)
    except AttributeError:  # numba's internals moved: leave the cache to numba
        return []
    return refresh(cache, module_digests())
