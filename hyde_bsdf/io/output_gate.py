"""The output gate: every file the package writes for a user passes here before the work starts.

Rules (``docs/troubleshooting.md``, "The file gates"):

* an existing target must be a regular file: a FIFO, a device (``/dev/null``), a socket or a
  folder is refused, never replaced; a symlink is followed only while it stays inside the output
  folder (then the file it names is written, and the link kept); one that leaves the folder
  (``/proc/self/fd/1``, ``../elsewhere``) is refused;
* no output may be an input of the same run (same file, whatever the spelling: compared by
  device and inode, and by resolved path for files not yet written);
* a replaced file keeps its mode, and its owner where the user may set it
  (:func:`hyde_bsdf.io.atomic.atomic_path`);
* the folder must be writable, a target in a sticky folder (``/tmp``) must be the user's own,
  a target that is a mount point cannot be renamed over, and the folder's file system must have
  the free space the outputs need -- all checked before any work;
* a run holds a lock on each of its outputs (:class:`OutputLock`) from the checks to the last
  rename, so a second run writing the same outputs fails at once with one line instead of mixing
  its files with the first run's.

Every refusal is a :class:`~hyde_bsdf.errors.UsageError` naming the file (cut to a readable
length) and the reason.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import os
import shutil
import stat
import tempfile
from pathlib import Path

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.io.input_gate import file_kind, is_stdin
from hyde_bsdf.io.memory import format_bytes
from hyde_bsdf.io.trust import UntrustedFileError, make_private_dir

__all__ = ["check_target", "check_not_input", "check_free_space", "check_folder", "OutputLock", "output_gate"]




def _mount_points() -> set:
    """Mount points of this process (``/proc/self/mountinfo``; bind mounts of single files too)."""
    try:
        with open("/proc/self/mountinfo", "rb") as fh:
            lines = fh.read(1 << 22).decode("utf-8", "replace").splitlines()
    except OSError:
        return set()
    points = set()
    for line in lines:
        parts = line.split(" ")
        if len(parts) > 4:     # octal escapes: \040 space, \011 tab, \012 newline, \134 backslash
            points.add(parts[4].replace("\\040", " ").replace("\\011", "\t").replace("\\012", "\n")
                       .replace("\\134", "\\"))
    return points


def _is_mount_point(path: Path, st, parent) -> bool:
    return st.st_dev != parent.st_dev or os.path.realpath(path) in _mount_points()


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.relative_to(folder)
    except ValueError:
        return False
    return True


def _follow_link(path: Path, folder: Path, what: str) -> Path:
    """The file a symlink ``path`` names, if it stays inside ``folder``; UsageError otherwise."""
    real = Path(os.path.realpath(path))
    if not _inside(real, Path(os.path.realpath(folder))):
        raise UsageError(f"{what} {shorten(path)} is a symbolic link to {shorten(real)}, outside its folder: "
                         f"not replaced; remove the link or give another name")
    return real


def check_target(path, what: str = "output file") -> Path:
    """The path to write for the output ``path``: refused (UsageError) if an existing target is not
    a regular file, is a symlink leaving its folder, is a mount point, or is someone else's file
    in a sticky folder.  A symlink inside the folder resolves to the file it names."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return path
    except OSError as exc:
        raise UsageError(f"{what} {shorten(path)}: cannot be checked ({exc.strerror or exc})") from None
    if stat.S_ISLNK(st.st_mode):
        real = _follow_link(path, folder, what)
        return check_target(real, what) if real != path else path
    if not stat.S_ISREG(st.st_mode):
        raise UsageError(f"{what} {shorten(path)} exists and is {file_kind(st.st_mode)}, not a regular file: "
                         f"not replaced; give a file name")
    parent = os.stat(folder)
    if _is_mount_point(path, st, parent):
        raise UsageError(f"{what} {shorten(path)} is a mount point: it cannot be replaced; give another name")
    if parent.st_mode & stat.S_ISVTX and os.geteuid() not in (0, st.st_uid, parent.st_uid):
        raise UsageError(f"{what} {shorten(path)} belongs to uid {st.st_uid} in a sticky folder (like /tmp): "
                         f"it cannot be replaced; give another name")
    return path


def _identity(path: Path):
    with contextlib.suppress(OSError):
        st = os.stat(path)
        return (st.st_dev, st.st_ino)
    return None


def check_not_input(outputs, inputs, what: str = "output file") -> None:
    """UsageError if any output is one of ``inputs`` (same inode, or the same resolved path)."""
    seen = {}
    for p in inputs:
        if p is None or is_stdin(p):
            continue
        seen[os.path.realpath(p)] = p
        ident = _identity(Path(p))
        if ident is not None:
            seen[ident] = p
    for out in outputs:
        for key in (os.path.realpath(out), _identity(Path(out))):
            if key is not None and key in seen:
                raise UsageError(f"{what} {shorten(out)} is the input {shorten(seen[key])} of this run: it would be "
                                 f"overwritten; write the outputs to another folder or name (-o)")


def check_free_space(folder, need_bytes: int, what: str = "the outputs", option: str = "free some space or "
                     "choose another folder (-o)", free: int | None = None) -> None:
    """UsageError if ``folder``'s file system (its nearest existing folder) has less than
    ``need_bytes`` free (``free``: the free bytes, measured when None); checked before the work."""
    folder = Path(folder)
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    free = shutil.disk_usage(folder).free if free is None else int(free)
    if need_bytes > free:
        raise UsageError(f"{what}: about {format_bytes(need_bytes)} needed, but {shorten(folder)} has "
                         f"{format_bytes(free)} free; {option}")


def check_folder(folder, what: str = "output folder") -> Path:
    """UsageError if the existing ``folder`` is a mount point (it could not be swapped by rename)
    or lies in a sticky folder (``/tmp``) that is someone else's while the folder is not the user's."""
    folder = Path(folder)
    try:
        st, up = os.lstat(folder), os.stat(folder.resolve().parent)
    except OSError:
        return folder
    if stat.S_ISDIR(st.st_mode) and _is_mount_point(folder, st, up):
        raise UsageError(f"{what} {shorten(folder)} is a mount point: its content cannot be replaced as a whole; "
                         f"give a folder inside it")
    if up.st_mode & stat.S_ISVTX and os.geteuid() not in (0, st.st_uid, up.st_uid):
        raise UsageError(f"{what} {shorten(folder)} belongs to uid {st.st_uid} in a sticky folder (like /tmp): "
                         f"it cannot be replaced; give another folder")
    return folder


def _lock_dir() -> Path:
    base = os.environ.get("XDG_RUNTIME_DIR") or tempfile.gettempdir()
    try:
        return make_private_dir(Path(base) / f"hyde-bsdf-locks-{os.geteuid()}")
    except (UntrustedFileError, OSError) as exc:
        raise UsageError(f"the lock folder cannot be used: {exc}") from None


class OutputLock:
    """Exclusive, non-blocking locks (``flock``) on each output path, in a private lock folder;
    released when the block ends or the process dies.  A path held by another run: UsageError."""

    def __init__(self, paths, what: str = "output"):
        self.paths = sorted({os.path.realpath(p) for p in paths})
        self.what = what
        self.fds = []

    def __enter__(self):
        folder = _lock_dir()
        try:
            for p in self.paths:
                self._lock(folder / (hashlib.sha256(os.fsencode(p)).hexdigest()[:32] + ".lock"), p)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _lock(self, lock_path: Path, target: str) -> None:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | os.O_CLOEXEC, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "?"
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise UsageError(f"{self.what} {shorten(target)} is being written by another run (pid {holder}); "
                                 f"wait for it to finish or write elsewhere (-o)") from None
            raise
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        self.fds.append(fd)

    def __exit__(self, *exc):
        for fd in self.fds:
            with contextlib.suppress(OSError):
                os.close(fd)               # closing releases the flock
        self.fds = []
        return False


@contextlib.contextmanager
def output_gate(outputs, *, inputs=(), need_bytes: int = 0, what: str = "output file"):
    """Check every output (:func:`check_target`, :func:`check_not_input`, :func:`check_free_space`)
    and hold :class:`OutputLock` on them for the block; yields the paths to write (symlinks inside
    their folder resolved).  ``need_bytes``: an upper bound of what the outputs take, which each
    of their folders must have free (the command estimates it from its options before the work)."""
    targets = [check_target(p, what) for p in outputs]
    check_not_input(targets, inputs, what)
    folders = {str(Path(p).parent) if str(Path(p).parent) else "." for p in targets}
    more = f" and {len(targets) - 1} more" if len(targets) > 1 else ""
    named = f"{what} {shorten(targets[0])}{more}" if targets else what
    for folder in sorted(folders):
        check_free_space(folder, need_bytes, named)
    with OutputLock(targets, what):
        yield targets
