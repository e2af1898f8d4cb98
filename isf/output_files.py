"""Writing isf's output files: checked before any work, written atomically, with the user's umask.

:func:`check_output_path` refuses a path that cannot become a regular file (a folder, a
symbolic link, a FIFO or device, a missing or unwritable folder), so a command can refuse it
before it plans or writes anything. :func:`write_atomically` writes a complete file or none at
all (a temporary file in the same folder, renamed over the target), with the permissions a
plain ``open(path, "w")`` would give (``0o666`` less the process's umask).
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

from .exceptions import OutputFileError

__all__ = ["check_output_path", "write_atomically"]


def check_output_path(path: str | Path, what: str = "output file") -> Path:
    """``path`` as a :class:`Path` once it is known it can become a regular file.

    Symbolic links are refused rather than followed or replaced: replacing one would silently
    cut the link, following it would write wherever it points.

    Raises:
        OutputFileError: the path is a folder, a symbolic link, a FIFO, socket or device, or
            its folder is missing or not writable.
    """
    path = Path(path)
    try:
        mode = path.lstat().st_mode
    except FileNotFoundError:
        mode = None
    except OSError as err:
        raise OutputFileError(f"{what} {path}: {err.strerror}: pass another path",
                              path=path) from None
    kind = None if mode is None or stat.S_ISREG(mode) else (
        "a folder" if stat.S_ISDIR(mode) else "a symbolic link" if stat.S_ISLNK(mode)
        else "a FIFO" if stat.S_ISFIFO(mode) else "not a regular file")
    if kind is not None:
        raise OutputFileError(f"{what} {path} is {kind}: name a regular file (isf replaces "
                              "it whole)", path=path)
    folder = path.parent
    if not folder.is_dir():
        raise OutputFileError(f"folder {folder} of {what} {path} does not exist: create it or "
                              "pass another path", path=path)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputFileError(f"folder {folder} of {what} {path} is not writable: pass another "
                              "path", path=path)
    return path


def _umask() -> int:
    """The process's umask: from ``/proc/self/status`` where Linux offers it (reading it with
    ``os.umask`` means setting it for a moment, which other threads could see)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_atomically(path: str | Path, data: bytes, what: str = "output file") -> Path:
    """Write ``data`` to ``path`` as a complete file or not at all, mode ``0o666 & ~umask``.

    Returns:
        the path written.

    Raises:
        OutputFileError: as :func:`check_output_path`, or the write failed (a full disk, an
            immutable file, a read-only file system); nothing is left behind.
    """
    path = check_output_path(path, what)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fchmod(f.fileno(), 0o666 & ~_umask())  # mkstemp makes 0o600
        os.replace(tmp, path)
        tmp = None
    except OSError as err:
        raise OutputFileError(f"cannot write {what} {path}: {err.strerror or err}: check the "
                              "folder's permissions and free space, or pass another path",
                              path=path) from err
    finally:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
    return path
