"""The package's own exceptions, and the one rule for what the command line makes of them.

Every exception the package raises on purpose is a :class:`HydeError` and also a standard one, so
Python callers can keep catching ``ValueError`` or ``OSError``:

* :class:`UsageError` (a ``ValueError``) -- a *user* mistake: a bad argument, input file, output
  path, scene or variant.  Messages name the parameter or file and the accepted range.
  :class:`InputFileError` is the kind for an input file that cannot be used (the measurement CSV,
  a ``.pbsdf`` table); :class:`UsageTypeError` (also a ``TypeError``) for a value of the wrong
  kind.
* :class:`OutputError` (an ``OSError``) -- writing an output failed (disk full, quota, I/O
  error); the previous files are unchanged (:mod:`hyde_bsdf.io.atomic`).
* :class:`RejectedResult` (a ``ValueError``) -- the work ran but its result is refused (an
  ill-posed fit with ``strict=True``).

The command line converts them in one place, :func:`hyde_bsdf.app.cli.main`: a UsageError, an
OSError or an OutputError is one line ``hyde-bsdf COMMAND: error: MESSAGE`` on stderr and exit
status 2; a RejectedResult is one line and exit status 1; any other exception (a library's, or a
bug) is one line naming its type and where, exit status 2 (``HYDE_BSDF_TRACEBACK=1`` shows its traceback).  Messages that echo a value the user gave cut it with :func:`shorten`.
"""
from __future__ import annotations

__all__ = ["HydeError", "UsageError", "UsageTypeError", "InputFileError", "OutputError", "RejectedResult",
           "one_line", "shorten", "shorten_values", "SHORTEN_LIMIT", "MESSAGE_VALUE_LIMIT"]

#: the longest user value a message echoes in full (characters)
SHORTEN_LIMIT = 80
#: the longest run a printed message keeps whole (a deep path stays whole; a 100 KB name does not)
MESSAGE_VALUE_LIMIT = 240


class HydeError(Exception):
    """Base of every exception the package raises on purpose."""


class UsageError(HydeError, ValueError):
    """A user mistake (argument, input or output path, scene): one-line message, exit 2."""


class UsageTypeError(UsageError, TypeError):
    """A user mistake of kind: a value of the wrong type (a string where a number belongs)."""


class InputFileError(UsageError):
    """An input file that cannot be used; the message names the file (and line, column, field)."""


class OutputError(HydeError, OSError):
    """Writing an output failed (disk full, quota, I/O error); the previous file(s) are unchanged."""


class RejectedResult(HydeError, ValueError):
    """The work ran, but its result is refused (exit status 1 on the command line)."""


def shorten(value, limit: int = SHORTEN_LIMIT) -> str:
    """``repr``-like text of a user value, cut to about ``limit`` characters: the start, an
    ellipsis with the number of characters left out, and the end (a 100 KB material name stays
    one readable line)."""
    import os
    if isinstance(value, os.PathLike):
        value = os.fspath(value)          # a path reads as the path, not PosixPath(...)
    return _cut(repr(value), limit)


def _cut(text: str, limit: int) -> str:
    """``text`` when at most ``limit`` characters, else its start, an ellipsis with the number of
    characters left out, and its end (the one form of a cut value, for both functions here)."""
    if len(text) <= limit:
        return text
    head, tail = (limit * 2) // 3, limit // 3 - 1
    return f"{text[:head]}...[{len(text) - head - tail} characters]...{text[-tail:]}"


def shorten_values(text: str, limit: int = MESSAGE_VALUE_LIMIT) -> str:
    """``text`` with every over-long value in it -- a quoted string, or a run without spaces --
    cut as :func:`shorten` cuts one (the command line applies it to every message it prints, so
    that a message built from a 100 KB argument stays one readable line)."""
    import re

    def cut(match):
        value = match.group(0)
        if " characters]..." in value:                           # already cut by shorten()
            return value
        return _cut(value, limit)

    return re.sub(r"'[^']*'|\"[^\"]*\"|\S+", cut, str(text))


def one_line(text) -> str:
    """``text`` with its lines joined by ' | ' (Mitsuba's parser messages span several lines).

    A Python traceback embedded in the text (Mitsuba re-raises a plugin constructor's exception
    with its traceback inside the message) is reduced to its last line, the exception itself.
    """
    lines = [part.strip() for part in str(text).strip().splitlines() if part.strip()]
    marker = "Traceback (most recent call last):"
    for i, line in enumerate(lines):
        if marker in line:
            head = line.split(marker, 1)[0].strip()
            lines = lines[:i] + ([head] if head else []) + lines[-1:]
            return " ".join(lines)
    return " | ".join(lines)
