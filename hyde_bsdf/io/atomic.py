"""Atomic output files: a temporary file in the same folder, fsync, ``os.replace``.

A reader -- or a process killed half-way, even by SIGKILL -- sees either the old file, intact, or
the new one, complete; never a truncated file.  Every file the package writes goes through
:func:`atomic_path` / :func:`atomic_open`; each file is renamed into place as soon as it is
complete.  On an exception (Ctrl-C, and SIGTERM/SIGHUP which the command line turns into one,
:mod:`hyde_bsdf.app.signals`) the temporary is removed and the old file stays.  After a SIGKILL,
which nothing can catch, the output checks of the next run in that folder remove the temporaries
of this host's dead processes (:func:`remove_stale_temporaries`).

Temporary names: ``.NAME.tmp-HOST-PID-RANDOM.SUFFIX`` (NAME cut to 100 bytes, so that a name
near the file system's limit still has a temporary; the suffix kept so that writers which pick
the format from it work).  :func:`atomic_folder` builds a folder's files in a hidden temporary
folder beside it and moves them in when the block completes, one rename per file.  A failed write (disk full, quota, I/O error) -- from Python, OpenEXR or
matplotlib -- is one :class:`OutputWriteError` naming the file and saying it is unchanged.  The
new file keeps the mode of the file it replaces, else gets what ``open`` gives (0666 & ~umask).
"""
from __future__ import annotations

import contextlib
import errno
import os
import re
import secrets
import shutil
import socket
import zlib
from pathlib import Path

from hyde_bsdf.errors import OutputError, UsageError, shorten

__all__ = ["atomic_path", "atomic_open", "atomic_folder", "OutputWriteError", "remove_stale_temporaries",
           "TEMP_NAME_RE", "on_temporary"]

_HOST = f"{zlib.crc32(socket.gethostname().encode()) & 0xffff:04x}"
#: the package's temporary names
TEMP_NAME_RE = re.compile(r"^\..*\.tmp-(?P<host>[0-9a-f]{4})-(?P<pid>\d+)-[0-9a-f]{6}(\.[^./]{1,16})?$")
_IO_ERRORS = {os.strerror(code): code for code in (errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EFBIG, errno.EROFS,
                                                   errno.EACCES)}


class OutputWriteError(OutputError):
    """A write of an output failed (disk full, quota, I/O error...); the previous file is unchanged."""


def _temp_path(path: Path, keep_suffix: bool = True) -> Path:
    head = os.fsdecode(os.fsencode(path.name)[:100])
    suffix = path.suffix if keep_suffix and 1 < len(path.suffix) <= 17 else ""
    return path.with_name(f".{head}.tmp-{_HOST}-{os.getpid()}-{secrets.token_hex(3)}{suffix}")


#: called with each temporary's path before it is made, or None (the command line's waiting
#: process removes them when it stops the work on a signal: :mod:`hyde_bsdf.app.signals`)
on_temporary = None


def _announce(tmp: Path) -> None:
    if on_temporary is not None:
        on_temporary(tmp)


def remove_stale_temporaries(folder) -> list[Path]:
    """Remove the temporaries in ``folder`` that a process of this host left when it was killed
    (their process is gone); nothing else is touched.  Returns what was removed."""
    removed = []
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            m = TEMP_NAME_RE.match(entry.name)
            if m and m["host"] == _HOST and not entry.is_symlink() and not _alive(int(m["pid"])):
                _remove(Path(entry.path))
                removed.append(Path(entry.path))
    return removed


def _remove(p: Path) -> None:
    with contextlib.suppress(OSError):
        shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        pass                               # another user's process
    return True


def _write_error(exc: BaseException, path: Path) -> OutputWriteError:
    """``exc`` (an OSError, or a writer's RuntimeError such as OpenEXR's) as one OutputWriteError."""
    code, reason = getattr(exc, "errno", None), getattr(exc, "strerror", None)
    if code is None or reason is None:
        code = next((c for t, c in _IO_ERRORS.items() if t.lower() in str(exc).lower()), errno.EIO)
        reason = os.strerror(code)
    return OutputWriteError(code, f"cannot write {str(path)!r}: {reason}; the earlier file is unchanged")


def _is_write_failure(exc: BaseException) -> bool:
    if isinstance(exc, OSError):
        return not isinstance(exc, OutputError)
    text = str(exc).lower()
    return isinstance(exc, RuntimeError) and not isinstance(exc, (NotImplementedError, RecursionError)) and (
        any(t.lower() in text for t in _IO_ERRORS) or "failed to write" in text or "cannot write" in text)


@contextlib.contextmanager
def atomic_path(path, mode: int | None = None):
    """Yield a temporary path beside ``path`` (same suffix); on normal exit it is written to disk
    (fsync) and renamed over ``path``; on an exception (KeyboardInterrupt included) it is removed
    and ``path`` is left as it was.  The new file gets ``mode``, else the mode of the regular file
    it replaces, else what ``open`` gives.  A failed write is an :class:`OutputWriteError`."""
    path = Path(path)
    tmp = _temp_path(path)
    try:
        try:
            _announce(tmp)
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
            yield tmp
            if mode is None:
                with contextlib.suppress(OSError):
                    mode = os.stat(path).st_mode & 0o7777 if path.is_file() else None
            if mode is None:
                umask = os.umask(0o022)
                os.umask(umask)
                mode = 0o666 & ~umask
            os.chmod(tmp, mode)
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())           # the data is on disk before the name points at it
            os.replace(tmp, path)
        except (OSError, RuntimeError) as exc:
            if not _is_write_failure(exc):
                raise
            raise _write_error(exc, path) from exc
    except BaseException:
        _remove(tmp)
        raise


@contextlib.contextmanager
def atomic_open(path, mode: str = "w", *, permissions: int | None = None, **kwargs):
    """``open(path, mode)`` that becomes visible under ``path`` only once the block completes
    (``permissions``: the new file's mode bits, see :func:`atomic_path`)."""
    if not mode.startswith("w"):
        raise UsageError(f"atomic_open: mode must be a write mode ('w', 'wb'), got {shorten(mode)}")
    with atomic_path(path, permissions) as tmp:
        with open(tmp, mode, **kwargs) as f:
            yield f


@contextlib.contextmanager
def atomic_folder(path):
    """Yield a fresh hidden folder beside the folder ``path``; when the block completes, each file
    in it replaces its namesake in ``path`` (created if missing; nothing else there is touched);
    on an exception it is removed and ``path`` is left as it was."""
    path = Path(path)
    tmp = _temp_path(path, keep_suffix=False)
    _announce(tmp)
    tmp.mkdir(0o700)
    try:
        yield tmp
        path.mkdir(parents=True, exist_ok=True)
        for root, _, files in os.walk(tmp):
            (path / Path(root).relative_to(tmp)).mkdir(exist_ok=True)
            for name in files:
                os.replace(Path(root) / name, path / Path(root).relative_to(tmp) / name)
    finally:
        _remove(tmp)
