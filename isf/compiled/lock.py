"""One process at a time compiles isf's kernels into a cache: :func:`compile_lock`.

Two processes compiling the same kernels into the same cache do not corrupt it (numba writes
each file under a temporary name and renames it), but each compiles everything, on a machine
whose cores they then share: twice the work, each finishing later than one alone would. So
:func:`isf.warming.warm_up` holds an exclusive lock on a file in the cache folder while it
compiles; a second process waits for it and then loads what the first compiled.

The lock is ``fcntl.flock`` (POSIX): the system releases it when its holder exits, even by
SIGKILL, so a killed compile never blocks later runs. Where ``fcntl`` is missing (Windows),
or the cache folder cannot be written, nothing is locked: processes then compile side by side
as numba alone would.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path

try:
    import fcntl
except ImportError:  # not POSIX: no lock (see the module docstring)
    fcntl = None

__all__ = ["LOCK", "compile_lock"]

LOCK = "isf-compile.lock"
"""The lock file's name, in the cache folder given to :func:`compile_lock`."""


@contextlib.contextmanager
def compile_lock(folder: Path | None, waiting: Callable[[], None] | None = None) -> Iterator[bool]:
    """Hold an exclusive lock on the file :data:`LOCK` in ``folder`` while the block runs,
    waiting first for any other process that holds it (``waiting()`` is called once before
    waiting). Yields whether the lock is held: False when no lock can be taken (no ``fcntl``,
    ``folder`` None or not writable), the block then runs unlocked."""
    if fcntl is None or folder is None:
        yield False
        return
    try:
        folder.mkdir(parents=True, exist_ok=True)
        handle = open(folder / LOCK, "ab")  # noqa: SIM115 (closed below, releasing the lock)
    except OSError:
        yield False
        return
    with handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if waiting is not None:
                waiting()
            fcntl.flock(handle, fcntl.LOCK_EX)
        except OSError:  # a file system without locks
            yield False
            return
        yield True  # closing the file releases the lock
