"""Files the package reads back from its own caches: trusted only if this user wrote them.

The rules are ssh's (``StrictModes``) for files that change what the program computes:

* a cache folder must be owned by this user (or root) and writable by no one else; each folder
  above it must be owned by this user or root and, if others may write to it, carry the sticky
  bit (``/tmp``): others then cannot rename or remove what this user put there;
* a cache file must be a regular file (never a FIFO, a device, a socket or a symlink: checked
  with ``lstat`` before it is opened, and opened with ``O_NONBLOCK | O_NOFOLLOW``, so nothing
  is ever waited on), owned by this user and writable by no one else;
* a secret (:func:`user_secret`: the per-user key that seals the cache files) must besides be
  readable by no one else (mode 0600).

A refusal is an :class:`UntrustedFileError` (an ``OSError``) whose one-line message names the
path, the reason and the fix.
"""
from __future__ import annotations

import contextlib
import os
import secrets
import stat
from pathlib import Path

from hyde_bsdf.io.input_gate import file_kind

__all__ = ["UntrustedFileError", "check_trusted_dir", "open_trusted", "user_secret", "make_private_dir",
           "SECRET_BYTES"]

#: length of the per-user secret
SECRET_BYTES = 32


class UntrustedFileError(OSError):
    """A cache file or folder that this user did not (only) write; the message says why."""



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


def _check_file(path: Path, st, private: bool) -> None:
    if not stat.S_ISREG(st.st_mode):
        raise UntrustedFileError(f"{str(path)!r} is {file_kind(st.st_mode)}, not a regular file: not opened")
    if not _owner_ok(st, allow_root=False):
        raise UntrustedFileError(f"{str(path)!r} is owned by uid {st.st_uid}, not by you (uid {os.geteuid()}): "
                                 f"not trusted; remove it")
    bad = (stat.S_IRWXG | stat.S_IRWXO) if private else (stat.S_IWGRP | stat.S_IWOTH)
    if st.st_mode & bad:
        who = "readable or writable" if private else "writable"
        fix = "chmod 600" if private else "chmod go-w"
        raise UntrustedFileError(f"{str(path)!r} is {who} by others (mode {stat.S_IMODE(st.st_mode):04o}): "
                                 f"not trusted; run {fix} on it")


def open_trusted(path, private: bool = False):
    """A binary file object of ``path`` if it passes the module's rules (checked with ``lstat``
    before opening, and again on the open descriptor), else :class:`UntrustedFileError`;
    FileNotFoundError if nothing is there.  Never blocks: a FIFO is refused before any open."""
    path = Path(path)
    before = os.lstat(path)
    _check_file(path, before, private)
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(path, flags)
    try:
        after = os.fstat(fd)
        if (after.st_dev, after.st_ino) != (before.st_dev, before.st_ino):
            raise UntrustedFileError(f"{str(path)!r} was replaced while it was being opened: not trusted")
        _check_file(path, after, private)
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _create_secret(path: Path) -> None:
    """Write a fresh secret beside ``path`` and link it into place (atomic; an existing one wins)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(3)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(secrets.token_bytes(SECRET_BYTES))
            fh.flush()
            os.fsync(fh.fileno())
        with contextlib.suppress(FileExistsError):   # another process was first: use its secret
            os.link(tmp, path)
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def user_secret(folder, name: str = ".key") -> bytes:
    """The per-user secret ``folder/name`` (created, mode 0600, if missing); the folder must be
    trusted (:func:`check_trusted_dir`).  :class:`UntrustedFileError` if the secret is not private."""
    path = check_trusted_dir(folder) / name
    try:
        fh = open_trusted(path, private=True)
    except FileNotFoundError:
        _create_secret(path)
        fh = open_trusted(path, private=True)
    with fh:
        key = fh.read(SECRET_BYTES + 1)
    if len(key) != SECRET_BYTES:
        raise UntrustedFileError(f"{str(path)!r} is not a {SECRET_BYTES}-byte key (damaged?): remove it")
    return key
