"""The package's one error convention for user mistakes.

:class:`UsageError` is a ``ValueError`` (so Python callers can keep catching ``ValueError``) that
marks a *user* mistake -- a bad argument, input file, output path or scene -- as opposed to a bug.
The command line (:func:`hyde_bsdf.cli.main` and each ``cli_main``) prints its message on one line,
``hyde-bsdf COMMAND: error: MESSAGE``, and exits with status 2; any other exception is a bug and
keeps its traceback.  Messages name the parameter or file and the accepted range.

May import: the standard library only (every subpackage may use it).
"""
from __future__ import annotations

__all__ = ["UsageError", "one_line"]


class UsageError(ValueError):
    """A user mistake (argument, input or output path, scene): one-line message, exit 2."""


def one_line(text) -> str:
    """``text`` with its lines joined by ' | ' (Mitsuba's parser messages span several lines)."""
    return " | ".join(part.strip() for part in str(text).strip().splitlines() if part.strip())
