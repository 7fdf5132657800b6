"""Small pieces the inverse modules share: luminance weights, sqrt(2), error lines.

May import: the standard library only.
"""
from __future__ import annotations

import math

#: luminance weights of linear sRGB (the film's R, G, B)
Y_WEIGHTS = (0.2126, 0.7152, 0.0722)
SQRT2 = math.sqrt(2.0)


def _first_line(exc) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:200] if text else type(exc).__name__

