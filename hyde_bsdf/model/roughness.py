"""Roughness parameters and their conversions.

The paper's roughness is the rms facet slope ``rms_slope = sqrt(2)*sigma_h/ell``
(sigma_h: rms height, ell: Gaussian correlation length; the slope of a Gaussian
surface along one axis then has standard deviation sqrt(2)*sigma_h/ell, so the
paper's value is the rms slope along one axis).  Beckmann's alpha, as used by
Mitsuba's ``roughconductor``, is ``alpha = 2*sigma_h/ell = sqrt(2)*rms_slope``.
"""
from __future__ import annotations

import math

import numpy as np

from hyde_bsdf.model.checks import real_scalar

__all__ = ["rms_slope_from", "alpha_from_rms_slope", "rms_slope_from_alpha", "check_rms_slope"]

SQRT2 = math.sqrt(2.0)


def rms_slope_from(sigma_h, ell):
    """The paper's roughness sqrt(2)*sigma_h/ell from rms height and correlation length (same units)."""
    sigma_h = np.asarray(sigma_h, dtype=float)
    ell = np.asarray(ell, dtype=float)
    if not np.all(np.isfinite(sigma_h)) or np.any(sigma_h <= 0):
        raise ValueError(f"sigma_h must be finite and > 0, got {sigma_h}")
    if not np.all(np.isfinite(ell)) or np.any(ell <= 0):
        raise ValueError(f"ell must be finite and > 0, got {ell}")
    out = SQRT2 * sigma_h / ell
    return float(out) if out.ndim == 0 else out


def alpha_from_rms_slope(rms_slope):
    """Beckmann alpha (Mitsuba's ``alpha``) = sqrt(2) * rms_slope."""
    return SQRT2 * rms_slope


def rms_slope_from_alpha(alpha):
    """The paper's rms slope = Beckmann alpha / sqrt(2)."""
    return alpha / SQRT2


def check_rms_slope(rms_slope, lo: float = 1e-4, hi: float = 50.0) -> float:
    """Validate a scalar rms slope, naming the parameter and the accepted range.

    TypeError for a complex, string, boolean or array value; ValueError for NaN, infinity
    or a value outside [lo, hi]."""
    return real_scalar("rms_slope", rms_slope, lo, hi)
