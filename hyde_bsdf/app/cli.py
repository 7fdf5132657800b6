"""``hyde-bsdf`` command line: one sub-command per module.

Each sub-command is a module of :mod:`hyde_bsdf.app` with a function ``cli_main(argv) -> int``;
this file only dispatches, so that importing the package stays cheap and no sub-command drags in
Mitsuba unless it needs it.  The library below (:mod:`hyde_bsdf.io`, ``model``, ``mitsuba``,
``mom``, ``fit``, ``render``, ``inverse``) raises exceptions and reports progress through
callbacks; the conversion to messages and exit codes happens here.

What happens when things go wrong, for every sub-command (handled once here):

* a user mistake (:class:`hyde_bsdf.errors.UsageError`: bad argument, input file, output path,
  scene, variant) -- one line ``hyde-bsdf COMMAND: error: MESSAGE`` on stderr, exit 2;
* an operating-system error on a file (missing, no permission, disk full, ...) -- one line, exit 2;
* a missing optional Python package -- one line naming it, exit 2;
* Ctrl-C -- ``hyde-bsdf COMMAND: interrupted``, exit 130 (outputs are atomic: the old files stay);
* SIGTERM / SIGHUP -- ``hyde-bsdf COMMAND: terminated (SIGTERM)``, exit 143 / 129: the signal
  unwinds like Ctrl-C, so hidden temporary files and ``.partial`` folders are removed
  (:func:`hyde_bsdf.io.atomic.install_signal_cleanup`; after a SIGKILL the next run removes them);
* a failed write (disk full, quota, I/O error) -- one line naming the file, exit 2; the earlier
  output set is unchanged (:class:`hyde_bsdf.io.atomic.OutputWriteError`);
* a closed output pipe (``hyde-bsdf fit data.csv | head``) -- quiet, exit 141 (as for SIGPIPE);
* anything else is a bug and keeps its Python traceback (exit 1).

Documented exit codes of the commands themselves stay: 1 for "fit did not converge" and for
"a validation check failed".
"""
from __future__ import annotations

import importlib
import os
import signal
import sys

#: sub-command -> (module, one-line help)
COMMANDS = {
    "demo": ("hyde_bsdf.app.demo", "the main job: demo pictures into a folder"),
    "render": ("hyde_bsdf.app.render", "render a scene to a Stokes EXR and polarization PNGs"),
    "fit": ("hyde_bsdf.app.fit", "fit n, k, rms_slope to a Mueller-matrix CSV or a measured_polarized table"),
    "export": ("hyde_bsdf.app.export", "write a hyde material as a measured_polarized table for C++ Mitsuba"),
    "invert": ("hyde_bsdf.app.invert", "recover roughness and index from a Stokes image"),
    "validate": ("hyde_bsdf.app.report.build", "run the validation report"),
}

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141


def _quiet_stdout() -> None:
    """After EPIPE: point stdout at /dev/null so that the interpreter's final flush is silent."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def _error(command: str, message: str) -> None:
    try:
        print(f"hyde-bsdf {command}: {message}", file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def main(argv: list[str] | None = None) -> int:
    from hyde_bsdf.errors import UsageError, one_line

    argv = list(sys.argv[1:] if argv is None else argv)
    command = argv[0] if argv else ""
    from hyde_bsdf.io.atomic import Terminated, install_signal_cleanup, remove_live_temporaries

    previous = install_signal_cleanup()
    try:
        if not argv or command in ("-h", "--help") or command not in COMMANDS:
            print("usage: hyde-bsdf COMMAND [options]\n\ncommands:")
            for name, (_, text) in COMMANDS.items():
                print(f"  {name:10s} {text}")
            if argv and command not in ("-h", "--help"):
                _error(command, f"error: unknown command {command!r}; one of {', '.join(COMMANDS)}")
            return 0 if argv and command in ("-h", "--help") else EXIT_USAGE
        module = importlib.import_module(COMMANDS[command][0])
        code = int(module.cli_main(argv[1:]) or 0)
        sys.stdout.flush()        # a closed pipe shows up here, inside the handler below
        return code
    except Terminated as exc:
        remove_live_temporaries()   # any a Python callback inside Mitsuba could not unwind
        _error(command, f"terminated ({exc})")
        return 128 + exc.signum
    except KeyboardInterrupt:
        remove_live_temporaries()
        _error(command, "interrupted")
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_BROKEN_PIPE
    except UsageError as exc:
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
    finally:
        for sig, handler in previous.items():   # in-process callers (tests) get their handlers back
            signal.signal(sig, handler)


if __name__ == "__main__":
    sys.exit(main())
