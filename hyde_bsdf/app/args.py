"""What every sub-command's argument parser shares: one-line errors, common argument types, and
the marks of the options that name files (:func:`reads`, :func:`writes`), from which
:func:`run_inputs` builds the set of files a run reads -- the inputs no output may replace.
"""
from __future__ import annotations

import argparse
import contextlib
from pathlib import Path

from hyde_bsdf.errors import HydeError, UsageError, one_line
from hyde_bsdf.io.input_gate import is_stdin
from hyde_bsdf.io.scene_files import scene_files

__all__ = ["Parser", "positive_int", "user_input", "quiet_option", "reads", "writes", "run_inputs"]


class Parser(argparse.ArgumentParser):
    """argparse whose mistakes are a :class:`~hyde_bsdf.errors.UsageError` (one line, exit 2)
    instead of the usage block and ``sys.exit``."""

    def error(self, message):
        raise UsageError(f"{message} (see {self.prog} --help)")


def reads(action, kind: str = "file"):
    """Mark an option (what ``add_argument`` returned) as naming files the run reads: ``kind``
    "file", "scene" (a Mitsuba scene: its whole file graph, :func:`~hyde_bsdf.io.scene_files.scene_files`)
    or "folder" (every file in it).  tests/test_cli_inputs.py fails on a file option left unmarked."""
    action.reads = kind
    return action


def writes(action):
    """Mark an option as naming a file or folder the run writes (checked by the output gate)."""
    action.writes = True
    return action


def run_inputs(parser: argparse.ArgumentParser, args, params: dict | None = None) -> list[Path]:
    """Every file a run of ``parser``'s command with ``args`` reads: the value of each option marked
    by :func:`reads` (standard input left out), a scene as its whole file graph (``params``: its
    ``$name`` values).  The output gate refuses an output that is one of them."""
    found = []
    for action in parser._actions:
        kind, value = getattr(action, "reads", None), getattr(args, action.dest, None)
        for v in (value if isinstance(value, list) else [value]) if kind else []:
            if v is None or is_stdin(v):
                continue
            if kind == "scene":
                found += scene_files(v, params)
            elif kind == "folder" and Path(v).is_dir():
                found += [p for p in Path(v).iterdir() if p.is_file()]
            else:
                found.append(Path(v))
    return found


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
