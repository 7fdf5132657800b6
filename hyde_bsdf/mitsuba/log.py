"""Mitsuba's log, once per run: :func:`log_once` lets a message that Mitsuba repeats for every scene
(``Monochrome mode enabled, setting film output pixel format to 'luminance'``, from every ``hdrfilm``
loaded in a mono variant) through the first time only.
"""
from __future__ import annotations

import contextlib

__all__ = ["REPEATED", "log_once"]

#: fragments of Mitsuba log messages that say the same thing for every scene of a run
REPEATED = ("Monochrome mode enabled",)


@contextlib.contextmanager
def log_once(fragments=REPEATED):
    """Within the block, a Mitsuba log message containing one of ``fragments`` is passed to the
    logger's appenders the first time only; every other message passes unchanged.  The appenders
    are restored afterwards."""
    import mitsuba as mi

    logger = mi.logger()
    inner = [logger.appender(i) for i in range(logger.appender_count())]

    class _Once(mi.Appender):
        def __init__(self):
            super().__init__()
            self.seen = set()

        def append(self, level, text):
            key = next((f for f in fragments if f in text), None)
            if key is not None:
                if key in self.seen:
                    return
                self.seen.add(key)
            for a in inner:
                a.append(level, text)

        def log_progress(self, progress, name, formatted, eta, ptr=None):
            for a in inner:
                a.log_progress(progress, name, formatted, eta, ptr)

    once = _Once()
    logger.clear_appenders()
    logger.add_appender(once)
    try:
        yield once
    finally:
        logger.clear_appenders()
        for a in inner:
            logger.add_appender(a)
