"""Shadowing/masking (visibility) functions G, pluggable into the specular term (Eq. 6).

Each shadowing model is written here three ways, one function each, and registered as one
record in :mod:`hyde_bsdf.model.terms`:

* G on the 2-D surface, the evaluator's (angles of Eq. 7): :func:`g_vgroove` (paper Eq. 12),
  :func:`g_smith`, :func:`g_none`, all called as ``g(cos_alpha, cos_beta, cos_i, cos_r, rms_slope)``;
* G in the plane of incidence of a 1-D surface (``mom/model1d.py``'s reduction, signed angles
  from the mean normal): :func:`g_vgroove_plane`, :func:`g_smith_plane`, :func:`g_none_plane`,
  called as ``g(theta_i, theta_r, rms_slope)``;
* the integrand W of the specular DHR (Eq. 14) in facet-slope space (:mod:`hyde_bsdf.model.dhr`'s
  quadrature): :func:`w_vgroove`, :func:`w_smith`, :func:`w_none`, called as
  ``w(u, r2, cos_i, rms_slope)``, and where the V-groove's W has kinks (:func:`vgroove_kinks_p`,
  :func:`vgroove_kinks_q`: the quadrature splits there).

- ``vgroove``: Torrance-Sparrow V-groove in Blinn's form, paper Eq. 12.
- ``smith``:   the Smith function of the Beckmann distribution, G = G1(i) G1(r),
               in its exact erf form (Mitsuba's roughconductor uses a rational fit of
               the same G1 with < 0.35 % error).
- ``none``:    G = 1, which with ``diffuse=False`` is the Priest-Germer pBRDF.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["g_vgroove", "g1_smith_beckmann", "g_smith", "g_none", "g_vgroove_plane", "g_smith_plane",
           "g_none_plane", "w_vgroove", "w_smith", "w_none", "vgroove_kinks_p", "vgroove_kinks_q"]

_SQRT_PI = math.sqrt(math.pi)


def _erf(x):
    # SciPy imported on first use: the plugin reads the term records without paying for it
    from scipy.special import erf
    return erf(x)


# ---------------------------------------------------------------- G on the 2-D surface (evaluator)
def g_vgroove(cos_alpha, cos_beta, cos_i, cos_r, rms_slope=None):
    """Paper Eq. 12: G = min(1, 2 cos(a) cos(tr)/cos(b), 2 cos(a) cos(ti)/cos(b)) (no roughness)."""
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
        g1 = 2.0 / (1.0 + _erf(a) + tail)
    return np.where(c > 0.0, g1, 0.0)


def g_smith(cos_alpha, cos_beta, cos_i, cos_r, rms_slope):
    """Uncorrelated Smith shadowing-masking G = G1(theta_i) G1(theta_r) (the facet angles unused)."""
    return g1_smith_beckmann(cos_i, rms_slope) * g1_smith_beckmann(cos_r, rms_slope)


def g_none(cos_alpha, cos_beta, cos_i, cos_r, rms_slope=None):
    """No shadowing (Priest-Germer): G = 1."""
    return np.ones_like(cos_i)


# ---------------------------------------------------------------- G in the plane (1-D surface)
def _beta_plane(theta_i, theta_r):
    """In-plane Eq. 7: the facet's local incidence angle beta = (theta_i + theta_r) / 2."""
    return 0.5 * (np.asarray(theta_i, float) + np.asarray(theta_r, float))


def g_vgroove_plane(theta_i, theta_r, rms_slope=None):
    """Eq. 12 in the plane: G = min(1, 2 cos(alpha) cos(theta_r)/cos(beta), 2 cos(alpha) cos(theta_i)/cos(beta)),
    alpha = (theta_r - theta_i)/2.  Zero where the facet faces away from source or observer (cos beta <= 0).

    The V-groove function is itself a 2-D derivation, so it is exact in the plane."""
    theta_i, theta_r = np.asarray(theta_i, float), np.asarray(theta_r, float)
    cb = np.cos(_beta_plane(theta_i, theta_r))
    ca = np.cos(0.5 * (theta_r - theta_i))
    with np.errstate(divide="ignore", invalid="ignore"):  # cos(beta) = 0 handled by the where below
        g = np.minimum(1.0, np.minimum(2.0 * ca * np.cos(theta_r) / cb, 2.0 * ca * np.cos(theta_i) / cb))
    return np.where(cb > 0.0, np.clip(g, 0.0, 1.0), 0.0)


def _smith_lambda_plane(theta, rms_slope):
    """Smith's Lambda for a 1-D Gaussian slope distribution (std rms_slope), mu = cot|theta|:
    (1/2) [sqrt(2/pi) (s/mu) exp(-mu^2 / (2 s^2)) - erfc(mu / (sqrt(2) s))]; 0 at normal incidence."""
    from scipy.special import erfc

    c = np.abs(np.cos(theta))
    sn = np.abs(np.sin(theta))
    with np.errstate(divide="ignore", invalid="ignore"):
        mu = c / sn
        lam = 0.5 * (math.sqrt(2.0 / math.pi) * (rms_slope / mu) * np.exp(-0.5 * (mu / rms_slope) ** 2)
                     - erfc(mu / (math.sqrt(2.0) * rms_slope)))
    return np.where(sn > 0, np.where(c > 1e-12, lam, np.inf), 0.0)


def g_smith_plane(theta_i, theta_r, rms_slope):
    """Smith's (1967) shadowing of a Gaussian surface in the plane: G = 1 / (1 + Lambda(ti) + Lambda(tr)).

    The bistatic form that treats source and observer as uncorrelated (pbrt's), for the 1-D
    surface's Gaussian slopes (std ``rms_slope``); zero where the facet faces away (cos beta <= 0).
    The statistical alternative to the V-groove G of Eq. 12 (Ref. 26 of the paper).
    """
    g = 1.0 / (1.0 + _smith_lambda_plane(np.asarray(theta_i, float), rms_slope)
               + _smith_lambda_plane(np.asarray(theta_r, float), rms_slope))
    return np.where(np.cos(_beta_plane(theta_i, theta_r)) > 0.0, g, 0.0)


def g_none_plane(theta_i, theta_r, rms_slope=None):
    """No shadowing in the plane: G = 1 on the facets that face source and observer (cos beta > 0)."""
    return (np.cos(_beta_plane(theta_i, theta_r)) > 0).astype(float)


# ---------------------------------------------------------------- Eq. 14 in slope space (the DHR)
# With the facet slopes (p, q), u = 1 - p tan(theta_i), r2 = p^2 + q^2 and
# X = 4u / (1 + r2) - 2 = 2 cos(theta_r) / cos(theta_i), the DHR is the Gaussian average of
# W = u G (model/dhr.py's module docstring); the reflected ray is above the horizon where X > 0.
def _x_ratio(u, r2):
    """X = 2 cos(theta_r) / cos(theta_i) of the facet with slopes r2 = p^2 + q^2."""
    return 4.0 * u / (1.0 + r2) - 2.0


def w_vgroove(u, r2, cos_i, rms_slope):
    """The V-groove's W = u G = min(u, 2, X), 0 below the horizon."""
    return np.maximum(np.minimum(np.minimum(u, 2.0), _x_ratio(u, r2)), 0.0)


def w_smith(u, r2, cos_i, rms_slope):
    """Smith's W = u G1(theta_i) G1(theta_r), cos(theta_r) = cos(theta_i) X / 2; 0 below the horizon."""
    X = _x_ratio(u, r2)
    cos_r = np.clip(0.5 * cos_i * X, 0.0, 1.0)
    w = u * g1_smith_beckmann(cos_i, rms_slope) * g1_smith_beckmann(cos_r, rms_slope)
    return np.where(X > 0.0, w, 0.0)


def w_none(u, r2, cos_i, rms_slope):
    """No shadowing: W = u above the horizon."""
    return np.where(_x_ratio(u, r2) > 0.0, u, 0.0)


def vgroove_kinks_p(theta, cos_i, sin_i, tan_i):
    """Where the inner integral of the V-groove's W is not smooth in p (a kink curve starts or ends):
    u = 2 at p = -cot; X = 2 meets q = 0 at p = 0 and p = -tan; X = u meets q = 0 where
    t p^3 - 3 p^2 - 3 t p + 1 = 0, i.e. p = tan((pi/2 - ti + m pi)/3)."""
    with np.errstate(divide="ignore", over="ignore"):    # theta_i = 0 or subnormal: -inf, clipped by the caller
        kinks = [-cos_i / sin_i, -tan_i]
    return kinks + [np.tan((0.5 * math.pi - theta + m * math.pi) / 3.0) for m in (-1, 0, 1)]


def vgroove_kinks_q(u, p, q_top):
    """The V-groove's kinks in q at a given p: X = 2 and X = u (conics), clipped to [0, q_top]."""
    q2_top = q_top * q_top
    kinks = [np.sqrt(np.clip(u - 1.0 - p * p, 0.0, q2_top))]                             # X = 2
    with np.errstate(divide="ignore", invalid="ignore"):
        kinks.append(np.sqrt(np.clip(4.0 * u / (u + 2.0) - 1.0 - p * p, 0.0, q2_top)))   # X = u
    return kinks
