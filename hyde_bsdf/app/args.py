"""What every sub-command's argument parser shares: one-line errors, common argument types.
"""
from __future__ import annotations

import argparse
import contextlib

from hyde_bsdf.errors import HydeError, UsageError, one_line

__all__ = ["Parser", "positive_int", "user_input", "quiet_option"]


class Parser(argparse.ArgumentParser):
    """argparse whose mistakes are a :class:`~hyde_bsdf.errors.UsageError` (one line, exit 2)
    instead of the usage block and ``sys.exit``."""

    def error(self, message):
        raise UsageError(f"{message} (see {self.prog} --help)")


def quiet_option(parser: argparse.ArgumentParser) -> None:
    """The ``-q``/``--quiet`` every sub-command has (read by :func:`hyde_bsdf.app.cli.main`)."""
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="no progress or summary lines on stderr (warnings and errors stay)")


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {value}")
    return value


@contextlib.contextmanager
def user_input(what: str = "", library: bool = False):
    """Inside a command, around a library call whose arguments and data come straight from the
    user: the library's own checks raise ``ValueError`` / ``TypeError`` (a Python caller's
    mistake), which here is the user's, so they leave as :class:`~hyde_bsdf.errors.UsageError`
    (``what`` prefixes the message; with ``library`` also the UsageErrors of the library's own
    argument checks, for a block that calls only the library).  The package's other exceptions
    pass unchanged, and :func:`hyde_bsdf.app.cli.main` alone turns them into a line and an exit
    status."""
    try:
        yield
    except UsageError as exc:
        if what and library:       # the library's checks raise UsageError: prefixed like ValueError
            raise type(exc)(f"{what}: {one_line(exc)}") from exc
        raise
    except HydeError:
        raise
    except (ValueError, TypeError) as exc:
        raise UsageError(f"{what}: {one_line(exc)}" if what else one_line(exc)) from exc
