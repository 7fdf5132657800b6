"""What every sub-command's argument parser shares: one-line errors, common argument types.

May import: anything (this is the application layer).
"""
from __future__ import annotations

import argparse

from hyde_bsdf.errors import UsageError

__all__ = ["Parser", "positive_int"]


class Parser(argparse.ArgumentParser):
    """argparse whose mistakes are a :class:`~hyde_bsdf.errors.UsageError` (one line, exit 2)
    instead of the usage block and ``sys.exit``."""

    def error(self, message):
        raise UsageError(f"{message} (see {self.prog} --help)")


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {value}")
    return value
