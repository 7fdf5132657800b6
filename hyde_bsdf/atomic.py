"""Atomic output files and folders, and output-path checks done before the work.

Files: :func:`atomic_path` / :func:`atomic_open` write to a temporary file in the same folder, then
``os.replace`` it over the target.  A reader -- or a process killed half-way, even by SIGKILL --
sees either the old file, intact, or the new one, complete; never a truncated file.  (After a
SIGKILL the hidden temporary ``.NAME.XXXX.tmp.SUFFIX`` stays behind beside the target; nothing
else can remove it.)  Every file the package writes (EXR, PNG, CSV, NPZ, HTML, the DHR cache) goes
through them.  The new file gets the permissions a plain ``open`` would give it (0666 & ~umask).

Folders: :func:`atomic_dir` builds a folder's whole content in a fresh hidden sibling and swaps it
in at the end, so that an interrupted run leaves the previous folder as it was (used by
``hyde-bsdf validate`` for its report).

Checks: :func:`check_output_path` / :func:`check_output_dir` raise
:class:`~hyde_bsdf.errors.UsageError` (a ``ValueError``) naming the path when it cannot be
written -- a directory where a file is expected, a parent that is a regular file, a folder that
cannot be created, no write permission, ``/proc`` -- so that commands refuse before long work.

May import: the standard library and :mod:`hyde_bsdf.errors` only (every subpackage may use it).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path

from hyde_bsdf.errors import UsageError

__all__ = ["atomic_path", "atomic_open", "atomic_dir", "check_output_path", "check_output_dir"]


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` (ending in the same suffix, so writers that choose
    the format from the extension still work); on normal exit it replaces ``path``, on an
    exception (KeyboardInterrupt included) it is removed and ``path`` is left as it was."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())       # mkstemp makes 0600; give what open() would give
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())                # the data is on disk before the name points at it
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


@contextlib.contextmanager
def atomic_dir(path):
    """Yield a fresh, empty hidden folder beside ``path``; on normal exit it takes the place of
    ``path`` (the previous folder, if any, is removed), on an exception it is removed and
    ``path`` is left untouched.  A symbolic link ``path`` is followed (its target is replaced).

    Between the two renames at the end there is an instant without ``path``; there is never one
    with a mixture of old and new files.
    """
    path = Path(path)
    if path.is_symlink():
        path = path.resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent))
    try:
        os.chmod(tmp, 0o777 & ~_umask())
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if path.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
        os.replace(path, old)                   # onto an empty folder: allowed for folders
    try:
        os.replace(tmp, path)
    except BaseException:
        if old is not None:
            os.replace(old, path)
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _probe(folder: Path, what: str, path: Path) -> None:
    try:
        fd, probe = tempfile.mkstemp(prefix=".hyde-bsdf.", suffix=".probe", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise UsageError(f"{what} {str(path)!r}: cannot write in {str(folder)!r} "
                         f"({exc.strerror or exc})") from None


def _make_folder(folder: Path, what: str, path: Path) -> None:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise UsageError(f"{what} {str(path)!r}: {str(folder)!r} is not a directory") from None
    except OSError as exc:
        raise UsageError(f"{what} {str(path)!r}: cannot create the folder {str(folder)!r} "
                         f"({exc.strerror or exc})") from None


def check_output_path(path, what: str = "output file", create_parent: bool = True) -> Path:
    """Check, before any long work, that the file ``path`` can be written; return it as a Path.

    Raises :class:`~hyde_bsdf.errors.UsageError` (a ``ValueError``) with a one-line message
    naming ``what`` and the path when ``path`` is a directory, its parent is not a directory (or
    cannot be created), or the parent is not writable (``/proc``, read-only file systems).
    With ``create_parent`` a missing parent folder is created.
    """
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{what} {str(path)!r} is a directory; give a file name")
    parent = path.parent
    if not parent.exists():
        if not create_parent:
            raise UsageError(f"{what} {str(path)!r}: the folder {str(parent)!r} does not exist")
        _make_folder(parent, what, path)
    if not parent.is_dir():
        raise UsageError(f"{what} {str(path)!r}: {str(parent)!r} is not a directory")
    _probe(parent, what, path)
    return path


def check_output_dir(path, what: str = "output folder", create: bool = True) -> Path:
    """Check, before any long work, that files can be written in the folder ``path``.

    Same errors as :func:`check_output_path`; a missing folder is created when ``create``.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UsageError(f"{what} {str(path)!r} is a regular file, not a folder")
    if not path.exists():
        if not create:
            raise UsageError(f"{what} {str(path)!r} does not exist")
        _make_folder(path, what, path)
    _probe(path, what, path)
    return path
