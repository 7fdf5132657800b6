"""Beckmann facet distribution, paper Eq. 8.

P(alpha) = l^2 exp(-l^2 tan^2(alpha) / (4 sigma_h^2)) / (4 pi sigma_h^2 cos^3(alpha))
         = exp(-tan^2(alpha) / (2 s^2)) / (2 pi s^2 cos^3(alpha)),
with s = rms_slope = sqrt(2) sigma_h / l.  P(alpha)/cos(alpha) is the usual
Beckmann normal distribution D(h) with alpha_B = sqrt(2) s; P cos^3 is the
isotropic Gaussian density of the facet slopes (p, q) with std s per axis.
"""
from __future__ import annotations

import numpy as np

__all__ = ["beckmann_P", "beckmann_D"]


def beckmann_P(cos_alpha, tan2_alpha, rms_slope):
    """Eq. 8, the facet distribution P(alpha; sigma_h, l) (1/sr per cos(alpha))."""
    s2 = rms_slope * rms_slope
    return np.exp(-tan2_alpha / (2.0 * s2)) / (2.0 * np.pi * s2 * cos_alpha ** 3)


def beckmann_D(cos_alpha, tan2_alpha, rms_slope):
    """P(alpha)/cos(alpha): the microfacet normal density D with int D cos(alpha) dw = 1."""
    s2 = rms_slope * rms_slope
    c2 = cos_alpha * cos_alpha
    return np.exp(-tan2_alpha / (2.0 * s2)) / (2.0 * np.pi * s2 * c2 * c2)
