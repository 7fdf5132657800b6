"""Private folders the package writes into (the output gate's lock folder): trusted only if
this user alone can write there.

The rules are ssh's (``StrictModes``): the folder must be owned by this user (or root) and
writable by no one else; each folder above it must be owned by this user or root and, if others
may write to it, carry the sticky bit (``/tmp``): others then cannot rename or remove what this
user put there.

A refusal is an :class:`UntrustedFileError` (an ``OSError``) whose one-line message names the
path, the reason and the fix.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

from hyde_bsdf.io.input_gate import file_kind

__all__ = ["UntrustedFileError", "check_trusted_dir", "make_private_dir"]


class UntrustedFileError(OSError):
    """A folder that this user did not (only) write; the message says why."""


def _owner_ok(st, allow_root: bool) -> bool:
    return st.st_uid == os.geteuid() or (allow_root and st.st_uid == 0)


def _check_dir_entry(path: Path, st, leaf: bool) -> None:
    if not stat.S_ISDIR(st.st_mode):
        raise UntrustedFileError(f"{str(path)!r} is {file_kind(st.st_mode)}, not a folder")
    if not _owner_ok(st, allow_root=True):
        raise UntrustedFileError(f"folder {str(path)!r} is owned by uid {st.st_uid}, not by you (uid "
                                 f"{os.geteuid()}) or root: its files are not trusted")
    others_write = st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)
    if others_write and (leaf or not st.st_mode & stat.S_ISVTX):
        raise UntrustedFileError(f"folder {str(path)!r} is writable by others (mode {stat.S_IMODE(st.st_mode):04o}): "
                                 f"its files are not trusted; run chmod go-w on it")


def check_trusted_dir(folder) -> Path:
    """``folder`` (resolved) if it and every folder above it pass the module's rules, else
    :class:`UntrustedFileError`; FileNotFoundError if it does not exist."""
    folder = Path(os.path.abspath(folder))
    real = Path(os.path.realpath(folder))
    _check_dir_entry(real, os.stat(real), leaf=True)
    for parent in real.parents:
        _check_dir_entry(parent, os.stat(parent), leaf=False)
    return real


def make_private_dir(folder) -> Path:
    """Create ``folder`` (mode 0700; missing parents with the default mode) and check it is trusted."""
    folder = Path(folder)
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    return check_trusted_dir(folder)
