"""The output gate: every file the package writes for a user is checked here before the work starts.

Rules (``docs/troubleshooting.md``, "The file gates"), each refusal one
:class:`~hyde_bsdf.errors.UsageError` naming the file and the reason:

* the folder exists (or can be created) and is writable; the name fits the file system and holds no
  control character (an ESC or a newline would reach the terminal and the XML snippets raw);
* an existing target is a regular file: a FIFO, a device (``/dev/null``), a socket or a folder is
  never replaced; a symlink is followed while it stays inside its folder (the file it names is
  written, the link kept) and refused where it leaves it (``/proc/self/fd/1``, ``../elsewhere``);
  a mount point, or someone else's file in a sticky folder (``/tmp``), cannot be renamed over;
* no output is a file the same run reads (:func:`output_gate`'s ``inputs``: same inode, or the
  same resolved path), and each folder has the free space the outputs need;
* one run at a time writes an output (:class:`~hyde_bsdf.resources.OutputLock`, held for the block).

The writes themselves are :mod:`hyde_bsdf.io.atomic`'s.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import stat
import unicodedata
from pathlib import Path

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.io.atomic import remove_stale_temporaries
from hyde_bsdf.io.input_gate import file_kind, is_stdin
from hyde_bsdf.resources import OutputLock, format_bytes

__all__ = ["check_output_path", "check_output_dir", "check_target", "check_not_input", "check_free_space",
           "output_gate"]


def _fits(path: Path, what: str) -> Path:
    """UsageError when ``path`` holds a control character, a part of it is longer than NAME_MAX, or the
    path than PATH_MAX."""
    control = sorted({c for c in str(path) if unicodedata.category(c) == "Cc"})
    if control:        # a pasted ESC or newline: it would reach the terminal ("wrote ...") and XML raw
        raise UsageError(f"{what} {shorten(str(path))}: the name holds control characters "
                         f"({', '.join(repr(c)[1:-1] for c in control)}); give a name without them")
    probe = next((p for p in (path.parent, *path.parent.parents) if os.path.isdir(p)), Path("."))
    name_max, path_max = os.pathconf(probe, "PC_NAME_MAX"), os.pathconf(probe, "PC_PATH_MAX")
    for part in path.parts:
        if len(os.fsencode(part)) > name_max:
            which = "the name" if part == path.name else f"the folder name {part[:30]!r}..."
            raise UsageError(f"{what} {str(path)!r}: {which} is {len(os.fsencode(part))} bytes, longer than "
                             f"the {name_max} bytes the file system allows; give a shorter name")
    if len(os.fsencode(str(path))) > path_max - 1 - 40:      # room for a temporary's tail
        raise UsageError(f"{what} {str(path)[:60]!r}...: the path is {len(os.fsencode(str(path)))} bytes, longer "
                         f"than the {path_max - 41} bytes the file system allows; give a shorter path")
    return path


def _writable_folder(folder: Path, what: str, path: Path, create: bool = True) -> None:
    """Create ``folder`` if missing; UsageError unless it is a folder one can write in.  Temporaries
    a killed run of this package left there are removed."""
    try:
        if create:
            folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise UsageError(f"{what} {str(path)!r}: {str(folder)!r} is not a directory") from None
    except OSError as exc:
        raise UsageError(f"{what} {str(path)!r}: cannot create the folder {str(folder)!r} "
                         f"({exc.strerror or exc})") from None
    if not folder.is_dir():
        raise UsageError(f"{what} {str(path)!r}: " + (f"{str(folder)!r} is not a directory" if folder.exists() else
                                                      f"the folder {str(folder)!r} does not exist"))
    probe = folder / f".hyde-bsdf-probe-{os.getpid()}"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.unlink(probe)
    except OSError as exc:
        raise UsageError(f"{what} {str(path)!r}: cannot write in {str(folder)!r} ({exc.strerror or exc})") from None
    remove_stale_temporaries(folder)


def check_output_path(path, what: str = "output file", create_parent: bool = True) -> Path:
    """The file ``path`` after the gate's checks (a symlink inside its folder resolved), before any
    long work; with ``create_parent`` a missing folder is created.  UsageError otherwise."""
    path = _fits(Path(path), what)
    if path.is_dir():
        raise UsageError(f"{what} {str(path)!r} is a directory; give a file name")
    if os.path.lexists(path):
        path = check_target(path, what)
    _writable_folder(path.parent, what, path, create_parent)
    return path


def check_output_dir(path, what: str = "output folder", create: bool = True) -> Path:
    """The folder ``path`` after the gate's checks (created when missing and ``create``)."""
    path = _fits(Path(path), what)
    if path.exists() and not path.is_dir():
        raise UsageError(f"{what} {str(path)!r} is a regular file, not a folder")
    _writable_folder(path, what, path, create)
    return path


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
        real = Path(os.path.realpath(path))
        if Path(os.path.realpath(folder)) not in real.parents:
            raise UsageError(f"{what} {shorten(path)} is a symbolic link to {shorten(real)}, outside its folder: "
                             "not replaced; remove the link or give another name")
        return check_target(real, what)
    if not stat.S_ISREG(st.st_mode):
        raise UsageError(f"{what} {shorten(path)} exists and is {file_kind(st.st_mode)}, not a regular file: "
                         "not replaced; give a file name")
    parent = os.stat(folder)
    if st.st_dev != parent.st_dev:
        raise UsageError(f"{what} {shorten(path)} is a mount point: it cannot be replaced; give another name")
    if parent.st_mode & stat.S_ISVTX and os.geteuid() not in (0, st.st_uid, parent.st_uid):
        raise UsageError(f"{what} {shorten(path)} belongs to uid {st.st_uid} in a sticky folder (like /tmp): "
                         "it cannot be replaced; give another name")
    return path


def _identities(path) -> list:
    keys = [os.path.realpath(path)]
    with contextlib.suppress(OSError):
        st = os.stat(path)
        keys.append((st.st_dev, st.st_ino))
    return keys


def check_not_input(outputs, inputs, what: str = "output file") -> None:
    """UsageError if any output is one of ``inputs`` (same inode, or the same resolved path)."""
    seen = {key: p for p in inputs if p is not None and not is_stdin(p) for key in _identities(p)}
    for out in outputs:
        hit = next((seen[key] for key in _identities(out) if key in seen), None)
        if hit is not None:
            raise UsageError(f"{what} {shorten(out)} is the input {shorten(hit)} of this run: it would be "
                             "overwritten; write the outputs to another folder or name")


def check_free_space(folder, need_bytes: int, what: str = "the outputs",
                     remedy: str = "free some space or choose another folder") -> None:
    """UsageError if ``folder``'s file system (its nearest existing folder) has less than
    ``need_bytes`` free; checked before the work."""
    folder = next((p for p in (Path(folder), *Path(folder).parents) if p.exists()), Path("."))
    free = shutil.disk_usage(folder).free
    if need_bytes > free:
        raise UsageError(f"{what}: about {format_bytes(need_bytes)} needed, but {shorten(folder)} has "
                         f"{format_bytes(free)} free; {remedy}")


@contextlib.contextmanager
def output_gate(outputs, *, inputs=(), need_bytes: int = 0, what: str = "output file"):
    """Check every output (:func:`check_target`), that none is one of ``inputs`` (every file the run
    reads), that each folder has ``need_bytes`` free (an upper bound of what the outputs take), and
    hold :class:`~hyde_bsdf.resources.OutputLock` on them for the block; yields the paths to write."""
    targets = [check_target(p, what) for p in outputs]
    check_not_input(targets, inputs, what)
    more = f" and {len(targets) - 1} more" if len(targets) > 1 else ""
    named = f"{what} {shorten(targets[0])}{more}" if targets else what
    for folder in sorted({str(Path(p).parent) for p in targets}):
        check_free_space(folder, need_bytes, named)
    with OutputLock(targets, what):
        yield targets
