"""Argument checks shared by the model's public functions: every refusal names the parameter.

NumPy's own conversions are too forgiving for a physics API: ``np.asarray(1+2j, float)``
drops the imaginary part with a warning, ``float("0.3")`` parses a string, ``float(True)``
is 1, and a shape mismatch surfaces as "operands could not be broadcast" without the
name of the argument.  These helpers refuse each of those with a one-line ``UsageTypeError``
(a ``TypeError``: wrong kind of value) or ``UsageError`` (a ``ValueError``: right kind, wrong
value or shape) naming the parameter and what it accepts.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

from hyde_bsdf.errors import UsageError, UsageTypeError, shorten

__all__ = ["real_array", "real_scalar", "check_bool", "broadcast_named"]


def _kind_name(value) -> str:
    a = np.asarray(value) if not isinstance(value, (str, bytes)) else None
    if a is None:
        return "a string"
    if a.dtype.kind == "c":
        return "complex"
    if a.dtype.kind == "b":
        return "boolean"
    if a.dtype.kind in "USV":
        return "a string"
    return type(value).__name__


def real_array(name: str, value, accepted: str) -> np.ndarray:
    """``value`` as a float64 array; TypeError unless it holds real numbers (not complex,
    strings or booleans), ValueError if any is NaN or infinite.  ``accepted`` completes
    the message ("radians in [0, pi]")."""
    if isinstance(value, (str, bytes)):
        raise UsageTypeError(f"{name} must be real numbers ({accepted}), got a string {shorten(value)}")
    try:
        a = np.asarray(value)
    except (ValueError, TypeError) as exc:           # ragged nested lists
        raise UsageError(f"{name} must be an array of real numbers ({accepted}): {exc}") from None
    if a.dtype.kind == "O":                          # e.g. a list mixing numbers and None
        if not all(isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)) for v in a.flat):
            raise UsageTypeError(f"{name} must be real numbers ({accepted}), got non-numeric values")
        a = a.astype(float)
    if a.dtype.kind not in "iuf":
        raise UsageTypeError(f"{name} must be real numbers ({accepted}), got {_kind_name(value)} values"
                        + (" (give the real and imaginary parts as separate parameters)"
                           if a.dtype.kind == "c" else ""))
    a = a.astype(float, copy=False)
    if not np.all(np.isfinite(a)):
        raise UsageError(f"{name} must be finite ({accepted}), got non-finite values")
    return a


def real_scalar(name: str, value, lo: float, hi: float) -> float:
    """``value`` as a float in [lo, hi]; TypeError for complex, string, boolean or array
    values, ValueError for NaN, infinity or a value outside the range."""
    rng = f"[{lo:g}, {hi:g}]"
    if isinstance(value, (bool, np.bool_)) or isinstance(value, (str, bytes)):
        raise UsageTypeError(f"{name} must be a real number in {rng}, got {_kind_name(value)} {shorten(value)}")
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, numbers.Complex) and not isinstance(value, numbers.Real):
        raise UsageTypeError(f"{name} must be a real number in {rng}, got complex {shorten(value)}")
    if not isinstance(value, numbers.Real):
        raise UsageTypeError(f"{name} must be a real number in {rng}, got {type(value).__name__} {shorten(value)}")
    v = float(value)
    if not math.isfinite(v) or not lo <= v <= hi:
        raise UsageError(f"{name} must be a finite number in {rng}, got {shorten(value)}")
    return v


def check_bool(name: str, value) -> bool:
    """A real boolean (True/False or NumPy's); TypeError for anything else, e.g. ``"no"``."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise UsageTypeError(f"{name} must be True or False, got {shorten(value)}")


def broadcast_named(**arrays) -> tuple:
    """The broadcast shape of named arrays; ValueError listing each name's shape if none exists."""
    try:
        return np.broadcast_shapes(*(a.shape for a in arrays.values()))
    except ValueError:
        shapes = ", ".join(f"{k} {v.shape}" for k, v in arrays.items())
        raise UsageError(f"{', '.join(arrays)} must broadcast to one shape, got {shapes}") from None
