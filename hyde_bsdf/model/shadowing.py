"""Shadowing/masking (visibility) functions G, pluggable into the specular term (Eq. 6).

- ``vgroove``: Torrance-Sparrow V-groove in Blinn's form, paper Eq. 12.
- ``smith``:   the Smith function of the Beckmann distribution, G = G1(i) G1(r),
               in its exact erf form (Mitsuba's roughconductor uses a rational fit of
               the same G1 with < 0.35 % error).
- ``none``:    G = 1, which with ``diffuse=False`` is the Priest-Germer pBRDF.
"""
from __future__ import annotations

import math

import numpy as np

from hyde_bsdf.errors import UsageError, shorten
from scipy.special import erf

__all__ = ["SHADOWING", "check_shadowing", "g_vgroove", "g1_smith_beckmann", "g_smith", "g_none", "visibility"]

SHADOWING = ("vgroove", "smith", "none")
_SQRT_PI = math.sqrt(math.pi)


def check_shadowing(name) -> str:
    """``name`` if it names a shadowing model (one of :data:`SHADOWING`); UsageError otherwise
    (the one check every interface that takes ``shadowing`` uses)."""
    if not isinstance(name, str) or name not in SHADOWING:
        raise UsageError(f"shadowing must be one of {SHADOWING}, got {shorten(name)}")
    return name


def g_vgroove(cos_alpha, cos_beta, cos_i, cos_r):
    """Paper Eq. 12: G = min(1, 2 cos(a) cos(tr)/cos(b), 2 cos(a) cos(ti)/cos(b))."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = 2.0 * cos_alpha / cos_beta
    return np.minimum(1.0, ratio * np.minimum(cos_i, cos_r))


def g1_smith_beckmann(cos_theta, rms_slope):
    """Smith masking for Beckmann slopes: G1 = 2 / (1 + erf(a) + exp(-a^2)/(a sqrt(pi))),
    a = cot(theta) / (sqrt(2) s).  G1 = 1 at theta = 0 (a = inf)."""
    c = np.clip(cos_theta, 0.0, 1.0)
    sin = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = c / (math.sqrt(2.0) * rms_slope * sin)
        tail = np.where(a > 26.0, 0.0, np.exp(-a * a) / (a * _SQRT_PI))   # exp underflows past 26
        g1 = 2.0 / (1.0 + erf(a) + tail)
    return np.where(c > 0.0, g1, 0.0)


def g_smith(cos_i, cos_r, rms_slope):
    """Uncorrelated Smith shadowing-masking G = G1(theta_i) G1(theta_r)."""
    return g1_smith_beckmann(cos_i, rms_slope) * g1_smith_beckmann(cos_r, rms_slope)


def g_none(cos_i):
    """No shadowing (Priest-Germer)."""
    return np.ones_like(cos_i)


def visibility(name, cos_alpha, cos_beta, cos_i, cos_r, rms_slope):
    """G for the named shadowing model (one of :data:`SHADOWING`)."""
    if name == "vgroove":
        return g_vgroove(cos_alpha, cos_beta, cos_i, cos_r)
    if name == "smith":
        return g_smith(cos_i, cos_r, rms_slope)
    if name == "none":
        return g_none(cos_i)
    raise UsageError(f"shadowing must be one of {SHADOWING}, got {shorten(name)}")
