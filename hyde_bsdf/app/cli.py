"""``hyde-bsdf`` command line: one sub-command per module.

Each sub-command is a module of :mod:`hyde_bsdf.app` with a function ``cli_main(argv) -> int``;
this file only dispatches, so that importing the package stays cheap and no sub-command drags in
Mitsuba unless it needs it.  The library below (:mod:`hyde_bsdf.io`, ``model``, ``mitsuba``,
``mom``, ``fit``, ``render``, ``inverse``) raises exceptions and reports progress through
callbacks; the conversion to messages and exit codes happens here.

What happens when things go wrong, for every sub-command (handled once here):

* a user mistake (:class:`hyde_bsdf.errors.UsageError`: bad argument, input file, output path,
  scene, variant) -- one line ``hyde-bsdf COMMAND: error: MESSAGE`` on stderr, exit 2;
* a refused result (:class:`hyde_bsdf.errors.RejectedResult`: an ill-posed fit with ``--strict``)
  or a numerical failure (``FloatingPointError``: a loss that became NaN) -- one line, exit 1;
* an operating-system error on a file (missing, no permission, disk full, ...) -- one line, exit 2;
* a missing optional Python package -- one line naming it, exit 2;
* Ctrl-C -- ``hyde-bsdf COMMAND: interrupted``, exit 130; SIGTERM / SIGHUP -- ``hyde-bsdf COMMAND:
  terminated (SIGTERM)``, exit 143 / 129, at any moment: the command runs as a child process that
  this one stops, removing its temporaries (:mod:`hyde_bsdf.app.signals`); the old files stay;
* a closed standard output (``>&-``) -- refused before the work, one line, exit 2;
* a failed write (disk full, quota, I/O error) -- one line naming the file, exit 2; that file is
  unchanged (:class:`hyde_bsdf.io.atomic.OutputWriteError`);
* a closed output pipe (``hyde-bsdf fit data.csv | head``) -- quiet, exit 141 (as for SIGPIPE);
* an executor that cannot finish the work (:class:`hyde_bsdf.mom.gather.ExecutorError`: a wait's limit
  reached, a dead cluster, a lost worker) -- one line, exit 2;
* anything else (a library's exception: NumPy's LinAlgError, a MemoryError, Mitsuba's RuntimeError, or a
  bug) -- one line naming its type and where in the package it was raised, exit 2
  (:func:`unexpected`; ``HYDE_BSDF_TRACEBACK=1`` shows the traceback instead).

Each sub-command raises; none converts an exception itself.  A Python warning is one line
``hyde-bsdf COMMAND: warning: MESSAGE``.  ``-q``/``--quiet`` (every sub-command has it) silences
progress and summary lines on stderr, never a warning or an error (:func:`hyde_bsdf.progress.set_quiet`).
``hyde-bsdf --version`` prints the package's version (:data:`hyde_bsdf.__version__`, from the
installed package's metadata).

Documented exit codes of the commands themselves stay: 1 for "fit did not converge" and for
"a validation check failed".
"""
from __future__ import annotations

import contextlib
import importlib
import os
import sys

from hyde_bsdf.app.signals import SUPERVISOR_ENV, handle_signals, supervise, work_setup

#: sub-command -> (module, one-line help)
COMMANDS = {
    "demo": ("hyde_bsdf.app.demo", "the main job: demo pictures into a folder"),
    "render": ("hyde_bsdf.app.render", "render a scene to a Stokes EXR and polarization PNGs"),
    "fit": ("hyde_bsdf.app.fit", "fit n, k, rms_slope to a Mueller-matrix CSV or a measured_polarized table"),
    "export": ("hyde_bsdf.app.export", "write a hyde material as a measured_polarized table for C++ Mitsuba"),
    "stokes": ("hyde_bsdf.app.stokes", "raw analyzer frames (DoFP mosaic or N angles) to a Stokes EXR with sigma"),
    "invert": ("hyde_bsdf.app.invert", "recover roughness and index from a Stokes image"),
    "accuracy": ("hyde_bsdf.app.accuracy", "how wrong the model may be at your geometry (the accuracy atlas)"),
    "validate": ("hyde_bsdf.app.report.build", "run the validation report"),
}

EXIT_USAGE = 2
EXIT_FAILED = 1
EXIT_BROKEN_PIPE = 141


def _quiet_stdout() -> None:
    """After EPIPE: point stdout at /dev/null so that the interpreter's final flush is silent."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def _error(command: str, message: str) -> None:
    """One line ``hyde-bsdf COMMAND: MESSAGE`` on stderr, the library's parameter names as the command
    line's flags (:mod:`hyde_bsdf.app.flags`), long values cut to a readable length."""
    from hyde_bsdf.app.flags import for_command_line
    from hyde_bsdf.errors import shorten_values

    if sys.stderr is None:          # closed: print(file=None) would write to standard output
        return
    try:
        sys.stderr.write(f"hyde-bsdf {command}: {shorten_values(for_command_line(message))}\n")   # one write
        sys.stderr.flush()
    except (OSError, ValueError):
        pass


def _usage(argv, command) -> int:
    """The top-level help, ``--version``, or an unknown command."""
    if command in ("--version", "-V"):
        from hyde_bsdf import __version__

        print(f"hyde-bsdf {__version__}")
        return 0
    print("usage: hyde-bsdf COMMAND [options]   (hyde-bsdf COMMAND --help; hyde-bsdf --version)\n\ncommands:")
    for name, (_, text) in COMMANDS.items():
        print(f"  {name:10s} {text}")
    if argv and command not in ("-h", "--help"):
        from hyde_bsdf.errors import shorten

        _error(command[:40], f"error: unknown command {shorten(command)}; one of {', '.join(COMMANDS)}")
        return EXIT_USAGE
    return 0 if argv else EXIT_USAGE


def _interrupt_in(exc):
    """The Ctrl-C (or SIGTERM) that caused ``exc`` (Mitsuba wraps it in a RuntimeError), or None."""
    cause = exc
    while cause is not None and not isinstance(cause, KeyboardInterrupt):
        cause = cause.__cause__ or cause.__context__
    return cause


def _one_line_warnings(command):
    """``warnings.showwarning`` printing ``hyde-bsdf COMMAND: warning: MESSAGE`` (one line)."""
    from hyde_bsdf.errors import one_line

    def show(message, category, filename, lineno, file=None, line=None):
        _error(command, f"warning: {one_line(message)}")

    return show


def _run(command: str, argv: list) -> int:
    import warnings

    from hyde_bsdf.errors import UsageError

    from hyde_bsdf.progress import set_quiet

    if sys.stdout is None:
        raise UsageError(CLOSED_STDOUT)
    quiet = any(a in ("-q", "--quiet") for a in argv)
    old_quiet, old_show = set_quiet(quiet), warnings.showwarning
    warnings.showwarning = _one_line_warnings(command)
    try:
        module = importlib.import_module(COMMANDS[command][0])
        code = int(module.cli_main(argv) or 0)
        sys.stdout.flush()        # a closed pipe shows up here, inside the handler of main
        return code
    finally:
        set_quiet(old_quiet)
        warnings.showwarning = old_show


def main(argv: list[str] | None = None) -> int:
    """``hyde-bsdf COMMAND ...``: run the sub-command and turn what it raises into one line and
    an exit status (the module docstring lists them).  From the console (no ``argv``) the command
    runs as a child process that this one waits on, so that a signal ends it at any moment with
    one line (:mod:`hyde_bsdf.app.signals`); with ``argv`` it runs in this process."""
    work = os.environ.pop(SUPERVISOR_ENV, None)
    console = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    command = argv[0] if argv else ""
    if command not in COMMANDS:
        return _usage(argv, command)
    if console and work is None:
        if _closed_stdout():
            _error(command, f"error: {CLOSED_STDOUT}")
            return EXIT_USAGE
        supervise(command, argv[1:], lambda message: _error(command, message))
    if work is not None:
        from hyde_bsdf.io import atomic

        atomic.on_temporary = work_setup(work)
    with handle_signals():          # in-process callers (tests) get their handlers back
        code = _convert(command, argv[1:])
    if work is not None:            # no wait for threads a library left running (dask's)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(code)
    return code


#: the refusal of a run whose standard output is closed (``>&-``)
CLOSED_STDOUT = ("standard output is closed (>&-): the results printed there would be lost; redirect it "
                 "(>/dev/null to discard them)")


def _closed_stdout() -> bool:
    """Whether standard output is closed; a closed standard input or error is opened on /dev/null
    (so that no file this run opens takes their place)."""
    closed = []
    for fd in (0, 1, 2):
        try:
            os.fstat(fd)
        except OSError:
            closed.append(fd)
            if fd != 1:
                os.open(os.devnull, os.O_RDONLY if fd == 0 else os.O_WRONLY)
    return 1 in closed


def _convert(command: str, argv: list) -> int:
    """The one place where exceptions become messages and exit codes."""
    from hyde_bsdf.app.signals import outcome
    from hyde_bsdf.errors import RejectedResult, UsageError, one_line

    try:
        return _run(command, argv)
    except KeyboardInterrupt as exc:          # Ctrl-C, SIGTERM, SIGHUP
        message, code = outcome(exc)
        _error(command, message)
        return code
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_BROKEN_PIPE
    except UsageError as exc:
        _error(command, f"error: {one_line(exc)}")
        return EXIT_USAGE
    except (RejectedResult, FloatingPointError) as exc:
        _error(command, f"error: {one_line(exc)}")
        return EXIT_FAILED
    except _executor_error() as exc:          # a wait's limit reached, a dead cluster, a lost worker: no bug
        _error(command, f"error: {one_line(exc)}")
        return EXIT_USAGE
    except ModuleNotFoundError as exc:
        if exc.name is None or exc.name.split(".")[0] == "hyde_bsdf":
            raise                 # our own module missing: a packaging bug, keep the traceback
        _error(command, f"error: the Python package {exc.name!r} is needed and not installed "
                        f"(pip install {exc.name.split('.')[0]})")
        return EXIT_USAGE
    except OSError as exc:
        where = f": {exc.filename!r}" if getattr(exc, "filename", None) else ""
        _error(command, f"error: {exc.strerror or one_line(exc)}{where}")
        return EXIT_USAGE
    except Exception as exc:  # noqa: BLE001 -- a library's exception (or a bug): one line, never a traceback
        cause = _interrupt_in(exc)          # Mitsuba wraps a Ctrl-C / SIGTERM in a RuntimeError
        if cause is not None:
            message, code = outcome(cause)
            _error(command, message)
            return code
        if os.environ.get(TRACEBACK_ENV):
            raise
        _error(command, f"error: {unexpected(exc)}")
        return EXIT_USAGE


def _executor_error() -> type:
    """:class:`hyde_bsdf.mom.gather.ExecutorError`, imported when an exception is being converted (the
    dispatcher itself stays cheap to import)."""
    from hyde_bsdf.mom.gather import ExecutorError

    return ExecutorError


#: set (to anything) to see the traceback of an unexpected exception instead of its one line
TRACEBACK_ENV = "HYDE_BSDF_TRACEBACK"


def unexpected(exc: BaseException) -> str:
    """The one line of an exception no part of the package turned into a message: what it is, where
    it was raised (the innermost frame in hyde_bsdf), and how to see the rest."""
    import traceback

    from hyde_bsdf.errors import one_line

    if isinstance(exc, MemoryError):
        what = "out of memory" + (f" ({one_line(exc)})" if str(exc) else "") + ": give smaller inputs"
    elif isinstance(exc, RecursionError):
        what = "an input is nested too deeply to be read (RecursionError)"
    else:
        what = f"{type(exc).__name__}: {one_line(exc) or 'no message'}"
    ours = [f for f in traceback.extract_tb(exc.__traceback__) if f"{os.sep}hyde_bsdf{os.sep}" in f.filename]
    where = f" in {ours[-1].filename.rsplit(os.sep + 'hyde_bsdf' + os.sep, 1)[1]}:{ours[-1].lineno}" if ours else ""
    return f"{what} (unexpected{where}; {TRACEBACK_ENV}=1 shows the traceback -- please report it)"


if __name__ == "__main__":
    sys.exit(main())
