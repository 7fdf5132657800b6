"""Progress reports: the library calls a callback; the command line decides what to show.

A long library function takes ``progress``: ``None`` or ``False`` (nothing), a callable
``progress(message: str)`` (called with one line of text, at most every
:data:`PROGRESS_SECONDS` where the function says so), or ``True``, which means "lines on
stderr" (:func:`stderr_lines`).  The library modules themselves never print: they call
:func:`as_callback` and then the callback.  ``hyde-bsdf`` passes :func:`stderr_lines`; its ``-q``
calls :func:`set_quiet`, which silences every stderr line of this module -- also those of work
deep inside the library that no command passes a callback to (the DHR table's build) -- but
no warning or error.
"""
from __future__ import annotations

import sys
import time

from hyde_bsdf.errors import UsageTypeError, shorten

__all__ = ["PROGRESS_SECONDS", "as_callback", "check_progress", "stderr_lines", "set_quiet", "Throttle",
           "EvaluationCounter"]

#: seconds between two progress lines of one task
PROGRESS_SECONDS = 3.0
_QUIET = [False]


def set_quiet(quiet: bool) -> bool:
    """Silence (True) or allow (False) every :func:`stderr_lines` line; returns the old setting."""
    old = _QUIET[0]
    _QUIET[0] = bool(quiet)
    return old


def stderr_lines(prefix: str = "[hyde-bsdf]"):
    """A progress callback writing ``PREFIX message`` lines on stderr (flushed)."""

    def report(message: str) -> None:
        if _QUIET[0]:
            return
        try:
            # one write of the whole line: a kill between the text and its newline would glue the next line to it
            sys.stderr.write((f"{prefix} {message}" if prefix else message) + "\n")
            sys.stderr.flush()
        except (OSError, ValueError):      # a closed stderr does not stop the work
            pass

    return report


def check_progress(progress, allow_none: bool = True) -> None:
    """UsageTypeError (a TypeError) unless ``progress`` is None, a bool or a callable."""
    if progress is None and allow_none:
        return
    if not (isinstance(progress, bool) or callable(progress) or type(progress).__name__ == "bool_"):
        raise UsageTypeError(f"progress must be True, False{', None' if allow_none else ''} or a callable "
                             f"progress(message), got {shorten(progress)}")


def as_callback(progress, prefix: str = "[hyde-bsdf]"):
    """The callable for ``progress`` (see the module docstring), or None for no reports."""
    check_progress(progress)
    if progress is None or progress is False or (not callable(progress) and not bool(progress)):
        return None
    if callable(progress):
        return progress
    return stderr_lines(prefix)


class Throttle:
    """Calls ``callback(message())`` at most every ``seconds`` (the first after ``seconds``).

    ``message`` is a function so that a skipped report costs nothing; ``elapsed`` is the time
    since the throttle was made.
    """

    def __init__(self, callback, seconds: float = PROGRESS_SECONDS):
        self.callback = callback
        self.seconds = seconds
        self.t0 = self.last = time.perf_counter()

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def __call__(self, message, force: bool = False) -> None:
        if self.callback is None:
            return
        now = time.perf_counter()
        if force or now - self.last >= self.seconds:
            self.last = now
            self.callback(message() if callable(message) else message)


class EvaluationCounter:
    """A fit's progress: counts its model evaluations (:meth:`tick`, with the residual vector) and
    reports the stage, the count and chi^2 through ``callback`` at most every ``seconds``;
    :meth:`done` says the total when the fit took that long.  ``unit`` names what is counted."""

    def __init__(self, callback, seconds: float = PROGRESS_SECONDS, unit: str = "evaluations"):
        self.throttle = Throttle(callback, seconds)
        self.stage = ""
        self.calls = 0
        self.unit = unit

    def tick(self, r) -> None:
        self.calls += 1
        self.throttle(lambda: f"fit: {self.stage}: {self.calls} {self.unit}, "
                              f"chi^2 = {float(r @ r):.6g}, {self.throttle.elapsed:.0f} s")

    def done(self) -> None:
        if self.throttle.elapsed >= self.throttle.seconds:
            self.throttle(f"fit: done, {self.calls} {self.unit} in {self.throttle.elapsed:.0f} s", force=True)
