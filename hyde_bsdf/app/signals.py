"""Signals: SIGTERM and SIGHUP end a command the way Ctrl-C does.

:func:`handle_signals` (the command line installs it for every sub-command) makes SIGTERM and
SIGHUP raise :class:`Terminated`, a ``KeyboardInterrupt``: the exception unwinds every ``with``
block, so each output being written is removed and the old file stays
(:func:`hyde_bsdf.io.atomic.atomic_path`).  :func:`outcome` gives the one line and the exit
status: Ctrl-C ``interrupted``, 130; SIGTERM ``terminated (SIGTERM)``, 143; SIGHUP 129.  A signal
that is ignored (``nohup`` ignores SIGHUP) stays ignored.
"""
from __future__ import annotations

import contextlib
import signal
import threading

__all__ = ["Terminated", "handle_signals", "outcome"]

#: exit status of Ctrl-C (128 + SIGINT)
EXIT_INTERRUPTED = 130


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP received: unwinds like Ctrl-C."""

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
    if isinstance(exc, Terminated):
        return f"terminated ({exc})", 128 + exc.signum
    return "interrupted", EXIT_INTERRUPTED
