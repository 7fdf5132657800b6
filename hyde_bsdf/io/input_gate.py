"""The input gate: every file the package reads for a user passes here first.

Rules (``docs/troubleshooting.md``, "The file gates"):

* an input is a regular file (a symlink to one is fine), or ``-`` for standard input; a FIFO,
  a device (``/dev/zero``), a socket or a folder is refused with one line, never opened, so
  nothing waits on it and nothing reads forever.  ``/dev/stdin`` and ``/dev/fd/0`` are spelled
  as standard input and read as ``-``;
* its size is checked against a limit *before* reading (standard input: read up to the limit
  and refused beyond it), so an endless stream cannot exhaust the memory;
* it is read once, into memory, and every later look (the file-type sniffing of ``fit``, the
  parser) works on those bytes: a pipe never loses its first bytes to a sniff;
* CSV text is split with a field limit (:data:`CSV_FIELD_LIMIT` characters), so a 200 KB cell
  is one line naming the row, not a parser traceback;
* a table's declared dimensions are multiplied in Python integers (no overflow) and checked
  against the file's size and the available memory before anything is allocated
  (:func:`check_dimensions`); a CSV's values are counted from its separators and checked the
  same way before it is decoded (:func:`check_csv_values`).

Every refusal is a :class:`~hyde_bsdf.errors.UsageError` naming the file (cut to a readable
length) and the limit.
"""
from __future__ import annotations

import csv
import io
import math
import os
import stat
import sys
from pathlib import Path

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.resources import COSTS, check_memory, format_bytes

__all__ = ["STDIN", "DEFAULT_LIMIT", "CSV_FIELD_LIMIT", "is_stdin", "file_kind", "check_input",
           "read_input", "read_text", "csv_rows", "check_dimensions", "check_csv_values"]

#: the spelling of standard input
STDIN = "-"
#: default size limit of one input (bytes)
DEFAULT_LIMIT = 1 << 30
#: longest CSV field accepted (characters): a number, a name or a comment fits many times over
CSV_FIELD_LIMIT = 4096
_STDIN_NAMES = {"-", "/dev/stdin", "/dev/fd/0", "/proc/self/fd/0"}
_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISLNK, "a symbolic link"),
          (stat.S_ISDIR, "a directory"))


def is_stdin(path) -> bool:
    return str(path) in _STDIN_NAMES


def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, for messages: 'a FIFO (named pipe)', 'a directory', ..."""
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def check_input(path, what: str = "input file", limit: int = DEFAULT_LIMIT, stdin: bool = True) -> Path | str:
    """``path`` (or :data:`STDIN`, where ``stdin`` allows it) after the gate's checks that need no
    read: it exists, is a regular file (following symlinks) of at most ``limit`` bytes.  UsageError
    otherwise."""
    if stdin and is_stdin(path):
        return STDIN
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise UsageError(f"{what} {shorten(path)} does not exist") from None
    except OSError as exc:
        raise UsageError(f"{what} {shorten(path)}: cannot be read ({exc.strerror or exc})") from None
    if not stat.S_ISREG(st.st_mode):
        raise UsageError(f"{what} {shorten(path)} is {file_kind(st.st_mode)}, not a regular file; give a file"
                         + (", or '-' to read standard input" if stdin else ""))
    if st.st_size > limit:
        raise UsageError(f"{what} {shorten(path)} is {format_bytes(st.st_size)}, more than the "
                         f"{format_bytes(limit)} accepted")
    return path


def _read_stdin(what: str, limit: int) -> bytes:
    stream = getattr(sys.stdin, "buffer", None)
    if stream is None:
        raise UsageError(f"{what}: standard input is not available")
    data = stream.read(limit + 1)
    if len(data) > limit:
        raise UsageError(f"{what} (standard input) is more than the {format_bytes(limit)} accepted")
    return data


def read_input(path, what: str = "input file", limit: int = DEFAULT_LIMIT) -> bytes:
    """The bytes of ``path`` (``-``: standard input), read once, after :func:`check_input`.

    The file is opened with ``O_NONBLOCK`` and checked again on the open descriptor, so one
    swapped for a FIFO between the check and the open is refused, not waited on."""
    checked = check_input(path, what, limit)
    if checked == STDIN:
        return _read_stdin(what, limit)
    try:
        fd = os.open(checked, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise UsageError(f"{what} {shorten(checked)}: cannot be read ({exc.strerror or exc})") from None
    with os.fdopen(fd, "rb") as fh:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise UsageError(f"{what} {shorten(checked)} is {file_kind(st.st_mode)}, not a regular file")
        os.set_blocking(fd, True)
        data = fh.read(min(st.st_size, limit) + 1)    # read(n) allocates n bytes first: never the whole limit
        if len(data) > st.st_size:                     # it grew while being read
            data += fh.read(limit + 1 - len(data))
    if len(data) > limit:
        raise UsageError(f"{what} {shorten(checked)} grew past the {format_bytes(limit)} accepted while being read")
    return data


def read_text(path, what: str = "input file", limit: int = DEFAULT_LIMIT, encoding: str = "utf-8-sig") -> str:
    """:func:`read_input` decoded (UTF-8, a byte-order mark dropped); UsageError for bytes that are not text."""
    data = read_input(path, what, limit)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        name = "standard input" if is_stdin(path) else shorten(path)
        raise UsageError(f"{what} {name} is not {encoding.split('-')[0].upper()} text "
                         f"(byte {exc.start}: {data[exc.start:exc.start + 1]!r})") from None


def csv_rows(text: str, what: str = "CSV file", field_limit: int = CSV_FIELD_LIMIT, **kwargs) -> list[list[str]]:
    """The rows of CSV ``text``; a field longer than ``field_limit`` characters, or a malformed
    row, is one UsageError naming the row."""
    old = csv.field_size_limit()
    csv.field_size_limit(field_limit)
    rows = []
    reader = csv.reader(io.StringIO(text, newline=""), **kwargs)
    try:
        for row in reader:
            rows.append(row)
    except csv.Error as exc:
        why = (f"a field is longer than the {field_limit} characters accepted" if "field limit" in str(exc)
               else f"{shorten(exc, 120)} (fields are limited to {field_limit} characters)")
        raise UsageError(f"{what}: row {reader.line_num}: {why}") from None
    finally:
        csv.field_size_limit(old)
    return rows


def check_dimensions(dims, itemsize: int, what: str, *, available_in_file: int | None = None,
                     option: str = "give a smaller table", max_elements: int | None = None) -> int:
    """The byte size of an array of shape ``dims`` (each a non-negative integer), computed without
    overflow, after checking it against ``available_in_file`` (the bytes the file holds for it),
    ``max_elements`` and the available memory (:func:`hyde_bsdf.resources.check_memory`)."""
    dims = [int(d) for d in dims]
    if any(d < 0 for d in dims):
        raise UsageError(f"{what}: negative dimension in {dims}")
    count = math.prod(dims)
    nbytes = count * int(itemsize)
    if max_elements is not None and count > max_elements:
        raise UsageError(f"{what}: dimensions {'x'.join(map(str, dims))} give {count} values, more than "
                         f"the {max_elements} accepted")
    if available_in_file is not None and nbytes > available_in_file:
        raise UsageError(f"{what}: dimensions {'x'.join(map(str, dims))} need {format_bytes(nbytes)}, but the "
                         f"file holds only {format_bytes(available_in_file)} for them (truncated or damaged)")
    return check_memory(nbytes, f"{what} ({'x'.join(map(str, dims))})", option)


def check_csv_values(raw: bytes, what: str) -> int:
    """The values the CSV bytes ``raw`` can hold -- one per comma or line end, plus one: a bound counted
    at memory speed, before a byte is decoded -- times the memory parsing one takes
    (:data:`~hyde_bsdf.resources.COSTS` ``csv_bytes_per_value``), checked against the available memory.
    Returns the bound."""
    values, per = raw.count(b",") + raw.count(b"\n") + raw.count(b"\r") + 1, COSTS.csv_bytes_per_value
    check_memory(values * per, f"{what} ({format_bytes(len(raw))}: at most {values} values, {per} B each to parse)",
                 "split it into smaller files")
    return values
