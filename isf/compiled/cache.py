"""numba's disk cache of isf's kernels, kept consistent with their sources.

numba stores each compiled kernel with a stamp of the file that defines it. But a kernel's
machine code also holds the code of the kernels it calls, which may be defined in other
modules, and the values of the module constants it reads: after an edit of
``fitting/_box_qp.py`` alone, the cached kernels of ``fitting/_finger_step.py`` would go on
running the old active set.

So before the first kernel of isf is defined (at the import of ``isf.compiled.healing``),
:func:`refresh_package` gives each module of the package (every ``*.py`` file in every
subfolder) a digest of its source and of the sources of every module of the package it
imports, directly or not (read from its import statements with ``ast``; importing ``a.b``
also runs ``a/__init__.py``), and deletes the cached kernels of each module whose digest
differs from the one recorded at the last check; those kernels compile afresh on first use.
An installed release never changes its sources, so this acts only after an upgrade (when
numba recompiles anyway) or after an edit of a checkout. The record also holds a stamp of the
sources' sizes and modification times: while that stamp is unchanged (every run but the first
after an edit) the digests are not computed again, and the check costs a directory listing
(milliseconds instead of a second of parsing).

Module keys are dotted paths relative to the package folder, ``__init__`` included
(``fitting.engine_kernel``, ``fitting.__init__``, ``__init__``). Each module's kernels live
in the folder numba's own locators choose for its source file (``__pycache__`` beside it, or
a folder under ``NUMBA_CACHE_DIR`` or numba's user cache), named ``<file stem>.<function>-...``.
"""

from __future__ import annotations

import ast
import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path

__all__ = ["RECORD", "cache_folder", "module_digests", "module_sources", "refresh",
           "refresh_installed", "refresh_package", "sources_stamp"]

RECORD = "isf-kernel-sources.json"
"""The file, in the cache folder of the package's ``__init__.py``, that records each module's
digest (``"digests"``) and the stamp of the sources they were computed from (``"stamp"``)."""

_PACKAGE = Path(__file__).resolve().parents[1]


def module_sources(package: Path) -> dict[str, Path]:
    """Every module of the folder ``package`` and its subfolders, by key (see the module
    docstring), sorted."""
    found = {}
    for path in sorted(package.rglob("*.py")):
        relative = path.relative_to(package).with_suffix("")
        if "__pycache__" not in relative.parts:
            found[".".join(relative.parts)] = path
    return found


def _imported(tree: ast.Module, key: str, package_name: str, modules: set[str]) -> set[str]:
    """The modules (keys of ``modules``) that the module ``key`` imports, with the ``__init__``
    of every package on the way."""
    parts = key.split(".")[:-1]  # the package holding this module (for __init__: itself)
    named: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            named.update(alias.name.split(".", 1)[1] for alias in node.names
                         if alias.name.startswith(package_name + "."))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = parts[:len(parts) - node.level + 1]
                if len(base) < len(parts) - node.level + 1:
                    continue  # above the package
                target = ".".join([*base, *([node.module] if node.module else [])])
            elif node.module == package_name or (node.module or "").startswith(package_name + "."):
                target = node.module.partition(".")[2]
            else:
                continue
            named.add(target)
            named.update(f"{target}.{alias.name}" if target else alias.name for alias in node.names)
    found = set()
    for name in named:
        pieces = name.split(".") if name else []
        for depth in range(len(pieces) + 1):  # the __init__ of each package on the way
            found.add(".".join([*pieces[:depth], "__init__"]))
        found.add(name)
    return found & modules


def module_digests(package: Path = _PACKAGE) -> dict[str, str]:
    """For each module of ``package`` (:func:`module_sources`): a sha256 of its source and of
    the sources of every module of the package it imports, directly or not."""
    sources = {key: path.read_bytes() for key, path in module_sources(package).items()}
    keys = set(sources)
    direct = {}
    for key, text in sources.items():
        try:
            tree = ast.parse(text)
        except SyntaxError:  # its import fails anyway; it depends on nothing here
            tree = ast.Module(body=[], type_ignores=[])
        direct[key] = _imported(tree, key, package.name, keys)
    own = {key: hashlib.sha256(text).hexdigest() for key, text in sources.items()}
    digests = {}
    for key in sources:
        closure, todo = {key}, [key]
        while todo:
            for imported in direct[todo.pop()] - closure:
                closure.add(imported)
                todo.append(imported)
        listing = "".join(f"{member} {own[member]}\n" for member in sorted(closure))
        digests[key] = hashlib.sha256(listing.encode()).hexdigest()
    return digests


def _placeholder() -> None:
    """A function for numba's cache locators, which read a function's first line number."""


def cache_folder(source: Path) -> Path | None:
    """The folder where numba caches the kernels defined in the file ``source``, as numba's own
    locators choose it; None when numba cannot cache there (or its internals moved)."""
    try:
        from numba.core import caching

        implementation = getattr(caching, "CacheImpl", None) or caching._CacheImpl
        for locator_class in implementation._locator_classes:
            locator = locator_class.from_function(_placeholder, str(source))
            if locator is not None:
                return Path(locator.get_cache_path())
    except Exception:  # numba's internals moved: leave the cache to numba
        return None
    return None


def sources_stamp(sources: Mapping[str, Path]) -> str:
    """A sha256 of the key, size and modification time (ns) of each module of ``sources``
    (:func:`module_sources`): it changes whenever a source is edited, added or removed."""
    listing = []
    for key, path in sources.items():
        status = path.stat()
        listing.append(f"{key} {status.st_size} {status.st_mtime_ns}\n")
    return hashlib.sha256("".join(listing).encode()).hexdigest()


def _read_record(record: Path) -> dict:
    try:
        recorded = json.loads(record.read_text())
    except (OSError, ValueError):
        return {}
    return recorded if isinstance(recorded, dict) else {}


def refresh(digests: Mapping[str, str], folders: Mapping[str, Path | None], record: Path,
            stamp: str = "") -> list[str]:
    """Delete the cached kernels (``<stem>.*.nbi`` and ``.nbc`` in ``folders[key]``, the stem
    being the key's last part) of each module whose digest in ``digests`` differs from the one
    recorded in the file ``record``, then record ``digests`` and ``stamp`` (written to a
    temporary file and renamed, so that a process reading it never sees half of it). Returns
    the keys of the modules whose kernels were deleted. Folders that cannot be read or written
    are left as they are (numba then does not cache there either)."""
    recorded = _read_record(record)
    if recorded.get("digests") == digests and recorded.get("stamp") == stamp:
        return []
    previous = recorded.get("digests")
    previous = previous if isinstance(previous, dict) else {}
    stale = sorted(key for key, digest in digests.items() if previous.get(key) != digest)
    try:
        for key in stale:
            folder, stem = folders.get(key), key.rpartition(".")[2]
            if folder is None:
                continue
            for path in [*folder.glob(f"{stem}.*.nbi"), *folder.glob(f"{stem}.*.nbc")]:
                path.unlink(missing_ok=True)
        record.parent.mkdir(parents=True, exist_ok=True)
        partial = record.with_name(f"{record.name}.{os.getpid()}.tmp")
        partial.write_text(json.dumps({"digests": dict(digests), "stamp": stamp}, indent=0,
                                      sort_keys=True))
        os.replace(partial, record)
    except OSError:
        return []
    return stale


def refresh_package(package: Path) -> list[str]:
    """:func:`refresh` for the package in the folder ``package``: its modules' digests, the
    folders where numba caches each module's kernels, and the record in the cache folder of its
    ``__init__.py`` (nothing is computed while the record's stamp matches the sources). Returns
    the keys of the modules whose kernels were deleted."""
    sources = module_sources(package)
    by_directory = {path.parent: cache_folder(path) for path in sources.values()}
    folders = {key: by_directory[path.parent] for key, path in sources.items()}
    root = folders.get("__init__")
    if root is None:
        return []
    stamp = sources_stamp(sources)
    if _read_record(root / RECORD).get("stamp") == stamp:  # no source changed since the record
        return []
    return refresh(module_digests(package), folders, root / RECORD, stamp)


def refresh_installed() -> list[str]:
    """:func:`refresh_package` for this installation of isf."""
    return refresh_package(_PACKAGE)
