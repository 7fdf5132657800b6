"""The package's one error convention for user mistakes.

:class:`UsageError` is a ``ValueError`` (so Python callers can keep catching ``ValueError``) that
marks a *user* mistake -- a bad argument, input file, output path or scene -- as opposed to a bug.
The command line (:func:`hyde_bsdf.app.cli.main` and each ``cli_main``) prints its message on one line,
``hyde-bsdf COMMAND: error: MESSAGE``, and exits with status 2; any other exception is a bug and
keeps its traceback.  Messages name the parameter or file and the accepted range.

May import: the standard library only (every subpackage may use it).
"""
from __future__ import annotations

__all__ = ["UsageError", "one_line"]


class UsageError(ValueError):
    """A user mistake (argument, input or output path, scene): one-line message, exit 2."""


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
