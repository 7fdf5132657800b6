"""Small pieces the inverse modules share: luminance weights, sqrt(2), progress and error lines, the
not-converged warning.

May import: the standard library only.
"""
from __future__ import annotations

import math
import sys

#: luminance weights of linear sRGB (the film's R, G, B)
Y_WEIGHTS = (0.2126, 0.7152, 0.0722)
SQRT2 = math.sqrt(2.0)


def _first_line(exc) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:200] if text else type(exc).__name__


def _log(msg, end="\n"):
    print(f"[invert] {msg}", file=sys.stderr, end=end, flush=True)


class NotConvergedWarning(UserWarning):
    """A fitted parameter that had not reached the minimum (in some texels, for a map): its standard
    errors there are NaN (they would understate the error); the value is not a result."""
