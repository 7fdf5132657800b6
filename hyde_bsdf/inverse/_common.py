"""Small pieces the inverse modules share: luminance weights, error lines, the not-converged
warning.
"""
from __future__ import annotations

import time

#: luminance weights of linear sRGB (the film's R, G, B)
Y_WEIGHTS = (0.2126, 0.7152, 0.0722)


def _first_line(exc) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:200] if text else type(exc).__name__


class NotConvergedWarning(UserWarning):
    """A fitted parameter that had not reached the minimum (in some texels, for a map): its standard
    errors there are NaN (they would understate the error); the value is not a result."""


def record_iteration(row: dict, history: list, t0: float, t_it: float, t_first):
    """Close one optimisation iteration begun at ``t_it`` (``time.perf_counter``): ``row["seconds"]`` = time
    since ``t0``, the row appended to ``history``; returns the first iteration's seconds (``t_first``, or
    this iteration's when it is the first)."""
    dt = time.perf_counter() - t_it
    row["seconds"] = time.perf_counter() - t0
    history.append(row)
    return dt if t_first is None else t_first


def seconds_per_iteration(history: list) -> float:
    """Mean seconds per iteration after the first (which includes the JIT compilation); NaN for one."""
    if len(history) < 2:
        return float("nan")
    return (history[-1]["seconds"] - history[0]["seconds"]) / (len(history) - 1)
