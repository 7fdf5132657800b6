"""Small pieces the inverse modules share: luminance weights, error lines, the not-converged
warning, a frozen optimisation step, the history of an optimisation and its CSV file.
"""
from __future__ import annotations

import csv
import gc
import time
from pathlib import Path

from hyde_bsdf.io.atomic import atomic_open

#: luminance weights of linear sRGB (the film's R, G, B)
Y_WEIGHTS = (0.2126, 0.7152, 0.0722)


def _first_line(exc) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:200] if text else type(exc).__name__


class NotConvergedWarning(UserWarning):
    """A fitted parameter that had not reached the minimum (in some texels, for a map): its standard
    errors there are NaN (they would understate the error); the value is not a result."""


def freeze_step(step):
    """``dr.freeze(step)``, called with the garbage collector paused (after Dr.Jit's queue is synchronised).

    The collector must not run while Dr.Jit records (the first call, and any call that records again): Dr.Jit
    arrays made from NumPy memory that wait in cyclic garbage are freed through host callbacks, which a recording
    cannot hold -- Dr.Jit aborts the process.  Paused for the call, the garbage waits for the next collection
    after it (instead of a full collection before every call: 30-70 ms each in a process with a large heap)."""
    import drjit as dr

    frozen = dr.freeze(step)

    def call(*args):
        dr.sync_thread()
        enabled = gc.isenabled()
        gc.disable()
        try:
            return frozen(*args)
        finally:
            if enabled:
                gc.enable()

    return call


def record_iteration(row: dict, history: list, t0: float, t_it: float, t_first):
    """Close one optimisation iteration begun at ``t_it`` (``time.perf_counter``): ``row["seconds"]`` = time
    since ``t0``, the row appended to ``history``; returns the first iteration's seconds (``t_first``, or
    this iteration's when it is the first)."""
    dt = time.perf_counter() - t_it
    row["seconds"] = time.perf_counter() - t0
    history.append(row)
    return dt if t_first is None else t_first


def write_history(path, history: list, columns, comment: str = "") -> Path:
    """The optimiser's history as a CSV file, written atomically (the one history writer): an optional
    ``# comment`` line, a header, one row per iteration with ``columns`` of its row -- integers as they
    are, other numbers to 7 significant digits."""
    with atomic_open(path, "w", newline="") as fh:
        if comment:
            fh.write(f"# {comment}\n")
        w = csv.writer(fh)
        w.writerow(columns)
        for row in history:
            w.writerow([row[c] if isinstance(row[c], int) else f"{row[c]:.7g}" for c in columns])
    return Path(path)


def seconds_per_iteration(history: list) -> float:
    """Mean seconds per iteration after the first (which includes the JIT compilation); NaN for one."""
    if len(history) < 2:
        return float("nan")
    return (history[-1]["seconds"] - history[0]["seconds"]) / (len(history) - 1)
