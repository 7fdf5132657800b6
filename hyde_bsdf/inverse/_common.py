"""Small pieces the inverse modules share: luminance weights, sqrt(2), progress and error lines.

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
