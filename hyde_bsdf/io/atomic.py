"""Atomic output files, output sets and folders; output-path checks done before the work.

Files: :func:`atomic_path` / :func:`atomic_open` write to a hidden temporary file in the same
folder, then ``os.replace`` it over the target.  A reader -- or a process killed half-way, even by
SIGKILL -- sees either the old file, intact, or the new one, complete; never a truncated file.
Every file the package writes (EXR, PNG, CSV, NPZ, HTML, the DHR cache) goes through them.  The new
file gets the permissions a plain ``open`` would give it (0666 & ~umask).

Output sets: inside ``with atomic_group():`` every :func:`atomic_path` write is only staged; the
renames happen together when the block ends, and only if every write succeeded.  A full disk or
any failed write while ``render`` writes its EXR and PNGs therefore leaves the previous set
complete and consistent (never a new EXR beside old PNGs).

A failed write (disk full, quota, I/O error, ...) -- from Python, OpenEXR or matplotlib -- ends in
:class:`OutputWriteError`, an ``OSError`` whose one-line message names the output file and says
that nothing was replaced.

Temporary names: ``.NAME.HHHHPID-RANDOM.tmp.SUFFIX`` (files) and ``.NAME.HHHHPID-RANDOM.partial``
/ ``.old`` (folders), where HHHH is a hash of the host name and PID the writing process.  They are
shortened (a hash of NAME replaces its tail) to fit the file system's NAME_MAX and PATH_MAX;
:func:`check_output_path` refuses, before any work, an output whose own name cannot fit.
Temporaries are removed when a block fails, on SIGTERM/SIGHUP (:func:`install_signal_cleanup`:
the signal becomes a :class:`Terminated` exception, so every ``with`` block cleans up), and --
after a SIGKILL, which nothing can catch -- by the next run that writes into the same folder
(:func:`remove_stale_temporaries`: only names of this pattern whose process is gone).

Folders: :func:`atomic_dir` builds a folder's content in a fresh hidden sibling and moves it in at
the end, keeping a manifest (``.hyde-manifest.json`` by default) of the files it wrote.  The next
run removes only files the manifest lists: a folder that also holds other files is refused
(:class:`~hyde_bsdf.errors.UsageError`) unless ``force=True``, and then those files are kept
(one whose name a new file takes is kept as ``NAME.orig``).  Nothing the package did not write
is ever deleted.

Checks: :func:`check_output_path` / :func:`check_output_dir` raise
:class:`~hyde_bsdf.errors.UsageError` (a ``ValueError``) naming the path when it cannot be
written -- a directory where a file is expected, a parent that is a regular file, a folder that
cannot be created, no write permission, ``/proc``, a name longer than the file system allows --
so that commands refuse before long work.
"""
from __future__ import annotations

import contextlib
import contextvars
import errno as _errno
import hashlib
import json
import os
import re
import secrets
import shutil
import signal
import socket
import stat
import threading
import time
from pathlib import Path

from hyde_bsdf.errors import OutputError, UsageError, shorten
from hyde_bsdf.io.output_gate import OutputLock, check_folder, check_target

__all__ = ["atomic_path", "atomic_open", "atomic_group", "atomic_dir", "check_output_path", "check_output_dir",
           "folder_target",
           "check_name_fits", "OutputWriteError", "Terminated", "install_signal_cleanup",
           "remove_stale_temporaries", "remove_live_temporaries", "read_manifest", "foreign_files",
           "check_dir_owned", "write_manifest", "write_error", "MANIFEST_NAME", "TEMP_NAME_RE", "LEGACY_TEMP_RE"]

#: the manifest atomic_dir keeps in the folders it manages (relative paths of the files it wrote)
MANIFEST_NAME = ".hyde-manifest.json"
#: our temporary names: .NAME.HHHHPID-RANDOM.KIND[SUFFIX]
TEMP_NAME_RE = re.compile(r"^\.(?P<name>.+)\.(?P<host>[0-9a-f]{4})(?P<pid>\d+)-(?P<rand>[a-z0-9]{6})"
                          r"\.(?P<kind>tmp|partial|old)(?P<suffix>\.[^/]*)?$")
#: a temporary of another host (a shared file system) is stale only when older than this (seconds)
FOREIGN_HOST_STALE_S = 24 * 3600.0
#: the names earlier versions gave temporaries (tempfile's 8 random characters, no pid): stale
#: when older than LEGACY_STALE_S
LEGACY_TEMP_RE = re.compile(r"^\.(?P<name>.+)\.[a-z0-9_]{8}\.(?:tmp(?:\.[^/]*)?|partial|old)$")
LEGACY_STALE_S = 3600.0

_HOST = hashlib.sha1(socket.gethostname().encode("utf-8", "replace")).hexdigest()[:4]
_LIVE: set = set()                      # temporaries of this process still in flight
_LIVE_LOCK = threading.Lock()
_CLEANED: set = set()                   # folders already swept for stale temporaries
_GROUP: contextvars.ContextVar = contextvars.ContextVar("hyde_atomic_group", default=None)


class OutputWriteError(OutputError):
    """A write of an output failed (disk full, quota, I/O error...); the previous file(s) are unchanged."""


class Terminated(KeyboardInterrupt):
    """SIGTERM / SIGHUP received (see :func:`install_signal_cleanup`): unwinds like Ctrl-C, cleaning up."""

    def __init__(self, signum=signal.SIGTERM):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)


# ---------------------------------------------------------------------------
# file-system limits and temporary names

def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _limit(folder: Path, name: str, default: int) -> int:
    try:
        value = os.pathconf(folder, name)
    except (OSError, ValueError):
        return default
    return value if value and value > 0 else default


def _nbytes(text: str) -> int:
    return len(os.fsencode(text))


def _truncate_bytes(text: str, nbytes: int) -> str:
    """The longest prefix of ``text`` whose encoding fits in ``nbytes`` (never a split character)."""
    raw = os.fsencode(text)[:max(nbytes, 0)]
    return os.fsdecode(raw).encode("utf-8", "ignore").decode("utf-8", "ignore") if raw else ""


def _temp_name(folder: Path, name: str, kind: str, suffix: str = "") -> str:
    """A fresh temporary name for ``folder/name`` that fits NAME_MAX and PATH_MAX (OSError if none can)."""
    tag = f"{_HOST}{os.getpid()}-{secrets.token_hex(3)}"
    tail = f".{tag}.{kind}{suffix}"
    name_max = _limit(folder, "PC_NAME_MAX", 255)
    path_max = _limit(folder, "PC_PATH_MAX", 4096)
    folder_bytes = _nbytes(str(folder)) + 1
    room = min(name_max, path_max - 1 - folder_bytes) - _nbytes(tail) - 1   # 1: the leading dot
    if _nbytes(name) <= room:
        return f".{name}{tail}"
    digest = hashlib.sha1(os.fsencode(name)).hexdigest()[:8]
    if room >= 9 + 8:                  # a readable head, then the hash of the whole name
        return f".{_truncate_bytes(name, room - 9)}~{digest}{tail}"
    if room >= 8:
        return f".{digest}{tail}"
    raise OSError(_errno.ENAMETOOLONG, "no temporary name fits beside this output (the path is too long)",
                  str(folder / name))


def check_name_fits(path, what: str = "output file") -> Path:
    """UsageError unless ``path``'s name fits NAME_MAX and the path, with a temporary beside it, PATH_MAX."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    probe = folder
    while probe != probe.parent:       # the limits of the nearest existing folder
        try:
            if probe.is_dir():
                break
        except OSError:
            pass
        probe = probe.parent
    name_max = _limit(probe, "PC_NAME_MAX", 255)
    path_max = _limit(probe, "PC_PATH_MAX", 4096)
    for i, part in enumerate(path.parts):
        if _nbytes(part) > name_max:
            which = "the name" if i == len(path.parts) - 1 else f"the folder name {part[:30]!r}..."
            raise UsageError(f"{what} {str(path)!r}: {which} is {_nbytes(part)} bytes, longer than "
                             f"the {name_max} bytes the file system allows; give a shorter name")
    shortest = _nbytes(str(folder)) + 1 + len(f".{'0' * 8}.{_HOST}{os.getpid()}-000000.partial{path.suffix}")
    if _nbytes(str(path)) > path_max - 1 or shortest > path_max - 1:
        raise UsageError(f"{what} {str(path)[:60]!r}...: the path is {_nbytes(str(path))} bytes, longer than "
                         f"the {path_max - 1} bytes the file system allows; give a shorter path")
    return path


def _register(p: Path) -> None:
    with _LIVE_LOCK:
        _LIVE.add(p)


def _unregister(p: Path) -> None:
    with _LIVE_LOCK:
        _LIVE.discard(p)


def _remove(p: Path) -> None:
    with contextlib.suppress(OSError):
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink()
    _unregister(p)


def remove_live_temporaries() -> int:
    """Remove every temporary file or folder this process has in flight; return how many."""
    with _LIVE_LOCK:
        items = list(_LIVE)
    for p in items:
        _remove(p)
    return len(items)


def _process_start(pid: int):
    """Start time (epoch seconds) of ``pid`` from /proc, or None when unknown."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
        with open("/proc/stat") as fh:
            btime = next(int(line.split()[1]) for line in fh if line.startswith("btime"))
        return btime + int(fields[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, StopIteration):
        return None


def _stale(match, mtime: float) -> bool:
    pid = int(match["pid"])
    if match["host"] != _HOST:
        return time.time() - mtime > FOREIGN_HOST_STALE_S
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True                     # its writer is gone
    except (PermissionError, OSError):
        pass                            # alive (another user's) or unknown: keep
    start = _process_start(pid)
    return start is not None and mtime < start - 2.0    # the pid was reused by a younger process


def remove_stale_temporaries(folder) -> list[Path]:
    """Remove temporaries of our name pattern in ``folder`` whose process is gone; return them.

    A temporary is stale when its process (same host) no longer runs, or runs but started after
    the temporary was last written (a reused pid).  One from another host (a shared file system)
    is removed only after FOREIGN_HOST_STALE_S, one named by an earlier version
    (``.NAME.XXXXXXXX.tmp.SUFFIX``, no pid) after LEGACY_STALE_S.  Nothing else is touched.
    """
    folder = Path(folder)
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        m = TEMP_NAME_RE.match(entry.name)
        legacy = m is None and LEGACY_TEMP_RE.match(entry.name)
        if not m and not legacy:
            continue
        try:
            mtime = entry.stat(follow_symlinks=False).st_mtime
        except OSError:
            continue
        if (time.time() - mtime > LEGACY_STALE_S) if legacy else _stale(m, mtime):
            p = Path(entry.path)
            with contextlib.suppress(OSError):
                if entry.is_dir(follow_symlinks=False):
                    shutil.rmtree(p)
                else:
                    p.unlink()
                removed.append(p)
    return removed


def _sweep_once(folder: Path) -> None:
    key = os.path.abspath(folder)
    if key not in _CLEANED:
        _CLEANED.add(key)
        remove_stale_temporaries(folder)


def _make_temp_file(path: Path) -> Path:
    folder = path.parent
    for _ in range(100):
        tmp = folder / _temp_name(folder, path.name, "tmp", path.suffix)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:
            continue
        os.close(fd)
        _register(tmp)
        return tmp
    raise OSError(_errno.EEXIST, "no free temporary name", str(path))


def _make_temp_dir(path: Path, kind: str) -> Path:
    folder = path.parent
    for _ in range(100):
        tmp = folder / _temp_name(folder, path.name, kind)
        try:
            os.mkdir(tmp, 0o700)
        except FileExistsError:
            continue
        _register(tmp)
        return tmp
    raise OSError(_errno.EEXIST, "no free temporary name", str(path))


# ---------------------------------------------------------------------------
# write errors

_ERRNO_BY_TEXT = {os.strerror(code): code for code in (_errno.ENOSPC, _errno.EDQUOT, _errno.EIO, _errno.EFBIG,
                                                       _errno.EROFS, _errno.EACCES, _errno.ENAMETOOLONG)}


def write_error(exc: BaseException, path) -> OutputWriteError:
    """``exc`` (an OSError, or a writer's RuntimeError such as OpenEXR's) as one OutputWriteError naming ``path``."""
    code = getattr(exc, "errno", None)
    reason = getattr(exc, "strerror", None)
    if code is None or reason is None:
        text = str(exc)
        code = next((c for t, c in _ERRNO_BY_TEXT.items() if t.lower() in text.lower()), _errno.EIO)
        reason = os.strerror(code)
    group = _GROUP.get()
    kept = "no output was replaced (the earlier files are unchanged)" if group is not None \
        else "the earlier file is unchanged"
    return OutputWriteError(code, f"cannot write {str(path)!r}: {reason}; {kept}")


# ---------------------------------------------------------------------------
# files and output sets

class _Group:
    def __init__(self):
        self.staged: dict = {}          # target -> temporary, in write order

    def stage(self, tmp: Path, path: Path) -> None:
        old = self.staged.pop(path, None)
        if old is not None and old != tmp:
            _remove(old)
        self.staged[path] = tmp

    def discard(self) -> None:
        for tmp in self.staged.values():
            _remove(tmp)
        self.staged.clear()

    def commit(self) -> None:
        items = list(self.staged.items())
        self.staged.clear()
        done = 0
        try:
            for path, tmp in items:
                try:
                    os.replace(tmp, path)
                except OSError as exc:
                    raise OutputWriteError(exc.errno, f"cannot replace {str(path)!r}: {exc.strerror}; {done} of "
                                                      f"{len(items)} outputs were replaced") from exc
                _unregister(tmp)
                done += 1
        except BaseException:
            for path, tmp in items[done:]:
                _remove(tmp)
            raise


@contextlib.contextmanager
def atomic_group():
    """Stage every :func:`atomic_path` write inside the block; rename them all at its end.

    The renames run only when the block completes, so a failed write (a full disk) or an
    interruption leaves every earlier output as it was -- the set stays consistent.  Nested
    groups join the outermost one.
    """
    if _GROUP.get() is not None:
        yield _GROUP.get()
        return
    group = _Group()
    token = _GROUP.set(group)
    try:
        yield group
    except BaseException:
        group.discard()
        raise
    finally:
        _GROUP.reset(token)
    group.commit()


def _keep_owner_and_mode(tmp: Path, path: Path, mode) -> None:
    """Give ``tmp`` the permission bits ``mode``; by default those of the regular file it replaces
    (a 0600 file stays 0600) and, where allowed, its owner and group, else what open() gives."""
    try:
        old = os.lstat(path)
    except OSError:
        old = None
    if old is not None and not (old.st_mode & 0o170000 == 0o100000):
        old = None                                   # only a regular file passes on its mode
    if mode is None:
        mode = (old.st_mode & 0o7777) if old is not None else 0o666 & ~_umask()
    if old is not None and (old.st_uid, old.st_gid) != (os.geteuid(), os.getegid()):
        with contextlib.suppress(OSError):           # root: owner and group; others: a group of theirs
            os.chown(tmp, old.st_uid if os.geteuid() == 0 else -1, old.st_gid)
    os.chmod(tmp, mode)


@contextlib.contextmanager
def atomic_path(path, mode: int | None = None):
    """Yield a temporary path beside ``path`` (ending in the same suffix, so writers that choose
    the format from the extension still work); on normal exit it replaces ``path`` (inside
    :func:`atomic_group`: when the group ends), on an exception (KeyboardInterrupt included) it
    is removed and ``path`` is left as it was.  An OSError of the write, or a writer's
    RuntimeError (OpenEXR), becomes :class:`OutputWriteError` naming ``path``.  The new file
    keeps the mode (and, where the user may, the owner and group) of the regular file it
    replaces, or gets ``mode`` when given, or what ``open`` gives (0666 & ~umask)."""
    path = Path(path)
    _sweep_once(path.parent)
    try:
        tmp = _make_temp_file(path)
    except OSError as exc:
        raise write_error(exc, path) from exc
    group = _GROUP.get()
    try:
        try:
            yield tmp
            _keep_owner_and_mode(tmp, path, mode)   # 0600 at creation
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())                # the data is on disk before the name points at it
            if group is None:
                os.replace(tmp, path)
        except (OSError, RuntimeError) as exc:
            if isinstance(exc, (OutputWriteError, NotImplementedError, RecursionError)):
                raise
            if isinstance(exc, RuntimeError) and not _looks_like_io(exc):
                raise
            raise write_error(exc, path) from exc
    except BaseException:
        _remove(tmp)
        raise
    if group is None:
        _unregister(tmp)
    else:
        group.stage(tmp, path)


def _looks_like_io(exc: BaseException) -> bool:
    text = str(exc).lower()
    return any(t.lower() in text for t in _ERRNO_BY_TEXT) or "failed to write" in text or "cannot write" in text


@contextlib.contextmanager
def atomic_open(path, mode: str = "w", *, permissions: int | None = None, **kwargs):
    """``open(path, mode)`` that becomes visible under ``path`` only once the block completes
    (``permissions``: the new file's mode bits, see :func:`atomic_path`)."""
    if not mode.startswith("w"):
        raise UsageError(f"atomic_open: mode must be a write mode ('w', 'wb'), got {shorten(mode)}")
    with atomic_path(path, permissions) as tmp:
        with open(tmp, mode, **kwargs) as f:
            yield f


# ---------------------------------------------------------------------------
# folders with a manifest

def _sha256(path: Path):
    """SHA-256 of the regular file ``path`` (a symlink, FIFO or device is not followed), or None."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0))
    except OSError:
        return None
    with os.fdopen(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        h = hashlib.sha256()
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _no_link_on_the_way(folder: Path, rel: str) -> bool:
    """True if ``folder/rel`` exists and none of its parts below ``folder`` is a symlink."""
    p = Path(folder)
    for part in Path(rel).parts:
        p = p / part
        try:
            if stat.S_ISLNK(os.lstat(p).st_mode):
                return False
        except OSError:
            return False
    return True


def _safe_rel(f) -> bool:
    return isinstance(f, str) and bool(f) and not Path(f).is_absolute() and ".." not in Path(f).parts


def _manifest(folder, manifest: str):
    """{"files": {rel: sha256 or None}, "dirs": set} of ``folder``'s manifest; None without one;
    empty when unreadable (it vouches for nothing)."""
    try:
        data = json.loads((Path(folder) / manifest).read_text(encoding="utf-8"))
        files, hashes, dirs = data["files"], data.get("sha256", {}), data.get("dirs", [])
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        files = hashes = dirs = None
    if not isinstance(files, list) or not isinstance(hashes, dict) or not isinstance(dirs, list):
        return {"files": {}, "dirs": set()}      # unreadable or malformed: it vouches for nothing
    return {"files": {f: hashes.get(f) for f in files if _safe_rel(f)}, "dirs": {d for d in dirs if _safe_rel(d)}}


def read_manifest(folder, manifest: str = MANIFEST_NAME):
    """The files the manifest of ``folder`` lists that are still as this program wrote them --
    regular files, reached without a symlink, with the SHA-256 the manifest recorded -- or None
    without a manifest.  Only these may ever be deleted (a file changed since, listed without a
    hash, or behind a symlink is not ours any more)."""
    data = _manifest(folder, manifest)
    if data is None:
        return None
    return {f for f, h in data["files"].items()
            if h and _no_link_on_the_way(Path(folder), f) and _sha256(Path(folder) / f) == h}


def _files_under(folder: Path) -> list[str]:
    out = []
    for root, dirs, files in os.walk(folder):
        rel = Path(root).relative_to(folder)
        for name in files + [d for d in dirs if os.path.islink(os.path.join(root, d))]:
            out.append((rel / name).as_posix())
    return sorted(out)


def _dirs_under(folder: Path) -> list[str]:
    """Real sub-folders of ``folder`` (relative paths; symlinks to folders are files here)."""
    out = []
    for root, dirs, _ in os.walk(folder):
        rel = Path(root).relative_to(folder)
        out += [(rel / d).as_posix() for d in dirs if not os.path.islink(os.path.join(root, d))]
    return sorted(out)


def foreign_files(folder, manifest: str = MANIFEST_NAME) -> list[str]:
    """What in ``folder`` (relative paths; folders end in '/') this program did not write, or
    changed since: files its manifest does not vouch for (:func:`read_manifest`) and folders it
    does not list -- not ours to delete.  Our own stale temporaries are removed first."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    remove_stale_temporaries(folder)
    listed = read_manifest(folder, manifest) or set()
    data = _manifest(folder, manifest) or {"dirs": set()}
    files = [f for f in _files_under(folder) if f != manifest and f not in listed
             and not TEMP_NAME_RE.match(Path(f).name)]
    return files + [d + "/" for d in _dirs_under(folder) if d not in data["dirs"]
                    and not TEMP_NAME_RE.match(Path(d).name)]


def check_dir_owned(path, manifest: str = MANIFEST_NAME, force: bool = False, what: str = "output folder") -> list[str]:
    """UsageError (one line naming the folder) when ``path`` holds files its manifest does not list,
    unless ``force``; return those files (kept by :func:`atomic_dir`)."""
    path = Path(path)
    foreign = foreign_files(path, manifest)
    if foreign and not force:
        shown = ", ".join(repr(f) for f in foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        had = "its manifest does not list" if read_manifest(path, manifest) is not None else \
            f"it has no {manifest}, so it is not a folder this program wrote"
        raise UsageError(f"{what} {str(path)!r} holds {len(foreign)} file(s) that no earlier run wrote ({shown}; "
                         f"{had}); give a new or empty folder, or pass --force to write beside them "
                         "(they are kept)")
    return foreign


def _unique_backup(dest: Path) -> Path:
    cand = dest.with_name(dest.name + ".orig")
    i = 1
    while cand.exists() or cand.is_symlink():
        cand = dest.with_name(f"{dest.name}.orig{i}")
        i += 1
    return cand


def write_manifest(folder, files, manifest: str = MANIFEST_NAME, dirs=(), hashes=None) -> None:
    """Write ``folder/manifest`` (atomically) listing ``files`` (relative paths) with their SHA-256
    (``hashes``, else read from ``folder``) and the sub-folders ``dirs`` this program created."""
    folder = Path(folder)
    hashes = dict(hashes) if hashes is not None else {f: _sha256(folder / f) for f in files}
    with atomic_open(folder / manifest, "w", encoding="utf-8") as fh:
        json.dump({"written_by": "hyde-bsdf", "note": "files this program wrote here (with their SHA-256) and the "
                   "folders it created; a rerun removes only these, and only while unchanged",
                   "files": sorted(files), "sha256": {f: hashes.get(f) for f in sorted(files)},
                   "dirs": sorted(dirs)}, fh, indent=1)
        fh.write("\n")


@contextlib.contextmanager
def atomic_dir(path, manifest: str = MANIFEST_NAME, force: bool = False, on_kept=None):
    """Yield a fresh, empty hidden folder beside ``path``; on normal exit its files take their place
    in ``path``, with a manifest listing them; on an exception it is removed and ``path`` is left
    untouched.  A symbolic link ``path`` is followed.

    * ``path`` new, empty, or holding only files its manifest lists (an earlier run's): swapped in
      whole (two renames: there is never a mixture of old and new files);
    * ``path`` holding other files: UsageError at entry, before any work, unless ``force``; with
      ``force`` the files of the old manifest are removed, the new ones moved in, every other file
      kept -- one whose name a new file takes is renamed ``NAME.orig`` and passed to ``on_kept(list)``.
    """
    path = folder_target(path, "output folder", follow_link=True)
    check_folder(path, "output folder")         # the output gate: a mount point, a sticky folder
    lock = OutputLock([path], "output folder").__enter__()    # one writer of the folder at a time
    try:
        check_dir_owned(path, manifest, force)
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(path.parent)
        tmp = _make_temp_dir(path, "partial")
    except BaseException:
        lock.__exit__(None, None, None)
        raise
    try:
        os.chmod(tmp, 0o777 & ~_umask())
        yield tmp
        new_files = [f for f in _files_under(tmp) if f != manifest]
        write_manifest(tmp, new_files, manifest, dirs=_dirs_under(tmp))
        kept = _move_in(tmp, path, new_files, manifest)
        if kept and on_kept is not None:
            on_kept(kept)
    finally:
        _remove(tmp)
        lock.__exit__(None, None, None)


def _move_in(tmp: Path, path: Path, new_files, manifest: str) -> list[Path]:
    if not path.exists() or (path.is_dir() and not any(path.iterdir())):
        os.replace(tmp, path)           # onto a missing or empty folder
        _unregister(tmp)
        return []
    foreign = foreign_files(path, manifest)
    if not foreign:                     # only the previous run's files: swap the folder whole
        old = _make_temp_dir(path, "old")
        os.replace(path, old)           # onto an empty folder: allowed for folders
        try:
            os.replace(tmp, path)
        except BaseException:
            os.replace(old, path)
            raise
        _unregister(tmp)
        _remove(old)
        return []
    # other files live here (force): list everything first, so a crash midway leaves no orphan
    old = _manifest(path, manifest) or {"dirs": set()}
    old_listed = read_manifest(path, manifest) or set()       # ours and unchanged: the only deletable
    hashes = {**{f: _sha256(path / f) for f in old_listed}, **{f: _sha256(tmp / f) for f in new_files}}
    new_dirs = _dirs_under(tmp)
    write_manifest(path, set(old_listed) | set(new_files), manifest, set(old["dirs"]) | set(new_dirs), hashes)
    for rel in sorted(set(old_listed) - set(new_files)):
        with contextlib.suppress(OSError):
            (path / rel).unlink()
    kept = []
    for rel in new_files:
        kept += _clear_the_way(path, rel, rel in old_listed)
        os.replace(tmp / rel, path / rel)
    for rel in sorted(set(old["dirs"]) - set(new_dirs), key=len, reverse=True):   # ours, now empty
        if _no_link_on_the_way(path, rel):
            with contextlib.suppress(OSError):
                os.rmdir(path / rel)
    write_manifest(path, new_files, manifest, [d for d in set(old["dirs"]) | set(new_dirs)
                                               if os.path.isdir(path / d)])
    return kept


def _clear_the_way(path: Path, rel: str, ours: bool) -> list[Path]:
    """Make ``path/rel`` writable without following anything: a symlink or a file where a folder
    of ``rel`` goes, or whatever holds ``rel``'s own name (unless ``ours``: an earlier run's
    unchanged file), is kept aside as ``NAME.orig``."""
    kept, p = [], path
    parts = Path(rel).parts
    for i, part in enumerate(parts):
        p = p / part
        last = i == len(parts) - 1
        try:
            st = os.lstat(p)
        except FileNotFoundError:
            if not last:
                os.mkdir(p)
            continue
        if (last and not ours) or (not last and not stat.S_ISDIR(st.st_mode)):   # a symlink is no folder
            backup = _unique_backup(p)
            os.replace(p, backup)
            kept.append(backup)
            if not last:
                os.mkdir(p)
    return kept


# ---------------------------------------------------------------------------
# signals

def install_signal_cleanup(signals=(signal.SIGTERM, signal.SIGHUP)):
    """Make SIGTERM (and SIGHUP) raise :class:`Terminated` in the main thread, so that every
    ``with`` block above removes its temporaries; return the previous handlers (or {} off the
    main thread).  A signal that is ignored (``nohup`` ignores SIGHUP) stays ignored.  The
    command line installs it for every sub-command."""
    if threading.current_thread() is not threading.main_thread():
        return {}

    def handler(signum, frame):
        raise Terminated(signum)

    previous = {}
    for sig in signals:
        with contextlib.suppress(ValueError, OSError, AttributeError):
            if signal.getsignal(sig) is signal.SIG_IGN:
                continue                # ignored on purpose (nohup ignores SIGHUP): keep it so
            previous[sig] = signal.signal(sig, handler)
    return previous


# ---------------------------------------------------------------------------
# checks before the work

def _probe(folder: Path, what: str, path: Path) -> None:
    try:
        probe = _make_temp_file(folder / "hyde-bsdf.probe")
        _remove(probe)
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
    naming ``what`` and the path when ``path`` is a directory, its name is longer than the file
    system allows, its parent is not a directory (or cannot be created), or the parent is not
    writable (``/proc``, read-only file systems).  With ``create_parent`` a missing parent folder
    is created.  Stale temporaries of an earlier killed run in the parent are removed.
    """
    path = Path(path)
    check_name_fits(path, what)
    if path.is_dir():
        raise UsageError(f"{what} {str(path)!r} is a directory; give a file name")
    if os.path.lexists(path):
        path = check_target(path, what)       # the output gate: special files, links, mounts, sticky
    parent = path.parent
    if not parent.exists():
        if not create_parent:
            raise UsageError(f"{what} {str(path)!r}: the folder {str(parent)!r} does not exist")
        _make_folder(parent, what, path)
    if not parent.is_dir():
        raise UsageError(f"{what} {str(path)!r}: {str(parent)!r} is not a directory")
    _probe(parent, what, path)
    _sweep_once(parent)
    return path


def folder_target(path, what: str = "output folder", follow_link: bool = False) -> Path:
    """``path`` as an output folder before any check of its contents: its name fits, a link
    followed to its target (``follow_link``), an existing non-folder refused (UsageError)."""
    path = Path(path)
    check_name_fits(path, what)
    if follow_link and path.is_symlink():
        path = path.resolve()
    if path.exists() and not path.is_dir():
        raise UsageError(f"{what} {str(path)!r} is a regular file, not a folder")
    return path


def check_output_dir(path, what: str = "output folder", create: bool = True) -> Path:
    """Check, before any long work, that files can be written in the folder ``path``.

    Same errors as :func:`check_output_path`; a missing folder is created when ``create``.
    """
    path = folder_target(path, what)
    if not path.exists():
        if not create:
            raise UsageError(f"{what} {str(path)!r} does not exist")
        _make_folder(path, what, path)
    _probe(path, what, path)
    _sweep_once(path)
    return path
