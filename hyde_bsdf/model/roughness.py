"""Roughness parameters and their conversions.

The paper's roughness is the rms facet slope ``rms_slope = sqrt(2)*sigma_h/ell``
(sigma_h: rms height, ell: Gaussian correlation length; the slope of a Gaussian
surface along one axis then has standard deviation sqrt(2)*sigma_h/ell, so the
paper's value is the rms slope along one axis).  Beckmann's alpha, as used by
Mitsuba's ``roughconductor``, is ``alpha = 2*sigma_h/ell = sqrt(2)*rms_slope``.
"""
from __future__ import annotations

import numpy as np

from hyde_bsdf.errors import UsageError

from hyde_bsdf.model.parameters import RMS_SLOPE, SQRT2, alpha_from_rms_slope, rms_slope_from_alpha

__all__ = ["rms_slope_from", "alpha_from_rms_slope", "rms_slope_from_alpha", "check_rms_slope"]


def rms_slope_from(sigma_h, ell):
    """The paper's roughness sqrt(2)*sigma_h/ell from rms height and correlation length (same units)."""
    sigma_h = np.asarray(sigma_h, dtype=float)
    ell = np.asarray(ell, dtype=float)
    if not np.all(np.isfinite(sigma_h)) or np.any(sigma_h <= 0):
        raise UsageError(f"sigma_h must be finite and > 0, got {sigma_h}")
    if not np.all(np.isfinite(ell)) or np.any(ell <= 0):
        raise UsageError(f"ell must be finite and > 0, got {ell}")
    out = SQRT2 * sigma_h / ell
    return float(out) if out.ndim == 0 else out


def check_rms_slope(rms_slope) -> float:
    """Validate a scalar rms slope, naming the parameter and the accepted range
    (:data:`hyde_bsdf.model.parameters.RMS_SLOPE`).

    TypeError for a complex, string, boolean or array value; ValueError for NaN, infinity
    or a value outside the range."""
    return RMS_SLOPE.check(rms_slope)
