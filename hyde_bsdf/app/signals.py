"""Signals: Ctrl-C, SIGTERM and SIGHUP end a command at any moment, with one line.

``hyde-bsdf`` runs each command in a child process, the *work*, and waits for it (:func:`supervise`).
The work blocks the three signals from its first instruction, and so does every process it
starts (pool workers, validation scripts): no library in it -- Dr.Jit and Mitsuba calling Python
back from C++, a module being imported, dask's threads -- can swallow a signal, turn it into
another error or abort on it.  The waiting process imports nothing heavy and sets its handlers in
its first lines; on a signal it stops the work and every process under it (SIGKILL; it is their
subreaper, so a pool worker whose parent died first is found too), removes the
temporaries the work had announced before making them (:data:`hyde_bsdf.io.atomic.on_temporary`),
prints one line and exits: Ctrl-C ``interrupted``, 130; SIGTERM ``terminated (SIGTERM)``, 143;
SIGHUP 129.  Outputs are renamed into place whole, so each is its old file or its new one.  A work
killed by something else (the kernel's out-of-memory killer) or aborting is one line too.

Before the waiting process's first line runs (the interpreter's own start) and after its last,
the signal's default action ends it: exit status 128 + the signal in a shell, nothing written.
A signal that is ignored (``nohup`` ignores SIGHUP) stays ignored.  Called in-process
(``hyde_bsdf.app.cli.main(argv)``), a command runs here, and :func:`handle_signals` makes SIGTERM
and SIGHUP unwind it like Ctrl-C.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

__all__ = ["Terminated", "handle_signals", "outcome", "supervise", "work_setup", "SUPERVISOR_ENV"]

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: tells the work the waiting process's pid and the file descriptor to announce its temporaries on
SUPERVISOR_ENV = "HYDE_BSDF_SUPERVISOR_FD"


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP (or, in the waiting process, SIGINT) received: unwinds like Ctrl-C."""

    def __init__(self, signum=signal.SIGTERM):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)


def _raise(signum, frame):
    raise Terminated(signum)


@contextlib.contextmanager
def handle_signals(signals=(signal.SIGTERM, signal.SIGHUP)):
    """SIGTERM and SIGHUP raise :class:`Terminated` inside the block (main thread only); the
    previous handlers come back after it."""
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in signals:
            if signal.getsignal(sig) is not signal.SIG_IGN:
                previous[sig] = signal.signal(sig, _raise)
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def outcome(exc: KeyboardInterrupt) -> tuple[str, int]:
    """The message and exit status of an interruption."""
    if isinstance(exc, Terminated) and exc.signum != signal.SIGINT:
        return f"terminated ({exc})", 128 + exc.signum
    return "interrupted", 128 + signal.SIGINT


def _descendants(pid: int) -> list[int]:
    """``pid`` and every process under it (Linux: from /proc; elsewhere ``pid`` alone)."""
    children = {}
    with contextlib.suppress(OSError):
        for entry in os.listdir("/proc"):
            with contextlib.suppress(OSError, ValueError, IndexError):
                with open(f"/proc/{entry}/stat", "rb") as fh:
                    children.setdefault(int(fh.read().rsplit(b")", 1)[1].split()[1]), []).append(int(entry))
    found, todo = [], [pid]
    while todo:
        found.append(todo.pop())
        todo += children.get(found[-1], [])
    return found


def _under_us() -> list[int]:
    """Every process under this one: the work, its processes, and (this process being their
    subreaper) those whose parent died first -- a pool's workers, multiprocessing's resource tracker."""
    return [pid for pid in _descendants(os.getpid()) if pid != os.getpid()]


def _stop(child, announced: int) -> None:
    """Kill the work and every process under it (stopped first, so none starts another; again until
    none is left: an orphan comes back to this process), then remove the temporaries it announced in
    the file ``announced``."""
    import shutil
    import time

    for sig in (signal.SIGSTOP, signal.SIGSTOP, *[signal.SIGKILL] * 50):
        pids = _under_us()
        if not pids:
            break
        for pid in pids:
            with contextlib.suppress(OSError):
                os.kill(pid, sig)
        with contextlib.suppress(ChildProcessError):
            while sig == signal.SIGKILL and os.waitpid(-1, os.WNOHANG)[0] > 0:   # reap: zombies are listed too
                pass
        if sig == signal.SIGKILL:
            time.sleep(0.01)
    with contextlib.suppress(ChildProcessError):
        child.wait()
    for name in os.pread(announced, os.fstat(announced).st_size, 0).split(b"\0"):
        with contextlib.suppress(OSError):
            shutil.rmtree(name) if os.path.isdir(name) and not os.path.islink(name) else os.unlink(name)


def work_setup(value: str):
    """In the work, first (``value``: the waiting process's ``PID:FD``): end with the waiting process
    (Linux), so that a ``kill -9`` of it leaves no work running; returns its announcement callback.
    The signals are blocked already (the mask is inherited) and ignored from here: the waiting process
    alone answers them (a Ctrl-C reaches the whole process group)."""
    parent, fd = (int(v) for v in value.split(":"))
    for sig in SIGNALS:      # and ignored: a library that unblocks them (multiprocessing's resource tracker
        signal.signal(sig, signal.SIG_IGN)      # start does) must not end the work; its processes inherit this
    with contextlib.suppress(Exception):
        import ctypes
        ctypes.CDLL(None).prctl(1, signal.SIGKILL)             # PR_SET_PDEATHSIG
    if os.getppid() != parent:
        os._exit(1)
    return lambda path: os.write(fd, os.fsencode(os.path.abspath(path)) + b"\0")


def supervise(command: str, argv: list, error) -> None:
    """Run ``hyde-bsdf COMMAND ARGV`` as the work (a child process), wait, and end this process
    with its exit status -- or, on a signal, as the module docstring says.  ``error(message)``
    prints one line.  Does not return."""
    for sig in SIGNALS:                          # first: from here on a signal is one line
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, _raise)
    child = announced = None
    try:
        import subprocess
        import tempfile

        with tempfile.TemporaryFile() as fh:     # unnamed: nothing to clean up
            announced = os.dup(fh.fileno())
        env = {**os.environ, SUPERVISOR_ENV: f"{os.getpid()}:{announced}"}
        with contextlib.suppress(Exception):     # Linux: the work's orphans come back here (see _stop)
            import ctypes
            ctypes.CDLL(None).prctl(36, 1)        # PR_SET_CHILD_SUBREAPER
        signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)  # the work inherits the mask: blocked all along
        try:
            child = subprocess.Popen([sys.executable, "-m", "hyde_bsdf.app.cli", command, *argv],
                                     pass_fds=(announced,), env=env)
        finally:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, SIGNALS)
        code = child.wait()
        signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)   # a signal from here waits for the end
        _checkpoint()                                       # (one that came before is raised here)
        if code < 0:
            error(f"error: the work ended on {signal.Signals(-code).name}"
                  + (" (out of memory?)" if code == -signal.SIGKILL else "") + "; the earlier files are unchanged")
            code = 128 - code
    except KeyboardInterrupt as exc:
        signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
        if child is not None:         # (ended or not: what it left under this process goes too)
            _stop(child, announced)
        message, code = outcome(exc)
        error(message)
        _exit(code, unblock=False)
    _exit(code, unblock=True)


def _checkpoint() -> None:
    """A Python call: a handler whose signal has arrived runs before it returns."""


def _exit(code: int, unblock: bool) -> None:
    """Flush and end with ``code``; with ``unblock``, a signal that arrived since the signals were
    blocked ends the process by its default action instead (never an exit 0 after a signal)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    if unblock:
        for sig in SIGNALS:
            if signal.getsignal(sig) is not signal.SIG_IGN:
                signal.signal(sig, signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, SIGNALS)
    os._exit(code)
