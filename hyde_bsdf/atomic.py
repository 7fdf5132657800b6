"""Atomic output files: write to a temporary file in the same folder, then ``os.replace``.

A reader (or a process killed half-way) sees either the old file, intact, or the new one,
complete; never a truncated file.  Every file the package writes (EXR, PNG, CSV, NPZ, HTML,
the DHR cache) goes through :func:`atomic_path` or :func:`atomic_open`.

May import: the standard library only (every subpackage may use it).
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_path", "atomic_open", "check_output_path"]


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` (same suffix, so writers that choose the format
    from the extension still work); on normal exit it replaces ``path``, on an exception it is
    removed and ``path`` is left as it was."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_open(path, mode: str = "w", **kwargs):
    """``open(path, mode)`` that becomes visible under ``path`` only once the block completes."""
    if not mode.startswith("w"):
        raise ValueError(f"atomic_open: mode must be a write mode ('w', 'wb'), got {mode!r}")
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as f:
        yield f


def check_output_path(path, what: str = "output file", create_parent: bool = True) -> Path:
    """Check, before any long work, that ``path`` can be written; return it as a Path.

    Raises ``ValueError`` with a one-line message naming ``what`` and the path when the path is
    a directory, its parent is not a directory (or cannot be created), or it is not writable.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{what} {str(path)!r} is a directory; give a file name")
    parent = path.parent
    if not parent.exists() and create_parent:
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"{what} {str(path)!r}: cannot create its folder ({exc.strerror})") from None
    if not parent.is_dir():
        raise ValueError(f"{what} {str(path)!r}: {str(parent)!r} is not a directory")
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".probe", dir=parent)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ValueError(f"{what} {str(path)!r}: cannot write in {str(parent)!r} ({exc.strerror})") from None
    return path
