"""The pBRDF's own reduction to a 1-D rough surface (2-D scattering in the plane of incidence).

Why
---
The paper's Fig. 6 compares its 3-D pBRDF (Eq. 17, a 2-D surface with an
isotropic slope distribution) with a MoM solution for a 1-D surface
``y = f(x)`` invariant along z.  Those are different surfaces: the 1-D surface
has slopes along x only and scatters in the plane.  For an apples-to-apples
test we rebuild the model from the same physics -- facet reflection, the
Torrance-Sparrow V-groove shadowing, and a diffuse term from the directional
hemispherical reflectance -- for the 1-D surface, so that its output is
directly (absolutely, not normalised at the specular angle) comparable with
:func:`hyde_bsdf.mom.scatter`.

Geometry (same as :mod:`hyde_bsdf.mom`)
----------------------------------------
Angles in radians, measured from the mean normal +y.  The source is at the
signed angle ``-theta_i`` (``theta_i`` in [0, pi/2)), the observer at the signed
angle ``theta_r`` in (-pi/2, pi/2); ``theta_r = +theta_i`` is specular
(the 3-D model's phi = pi for theta_r >= 0, phi = 0 for theta_r < 0).  A facet
tilted by the signed angle ``alpha`` (normal at angle alpha from +y) mirrors the
source into ``theta_r = theta_i + 2 alpha``:

    alpha = (theta_r - theta_i) / 2,     beta = (theta_i + theta_r) / 2,

``beta`` being the local angle of incidence (and reflection) on the facet.
These are the in-plane forms of the paper's Eq. 7.

Pieces (each the 1-D counterpart of a paper equation)
------------------------------------------------------
* :func:`facet_pdf` (Eq. 8): a 1-D Gaussian surface with height deviation
  sigma_h and correlation length ell has Gaussian slopes s = tan(alpha) with
  standard deviation ``rms_slope = sqrt(2) sigma_h / ell``, so the pdf of the
  facet angle per radian is  p(alpha) = N(tan alpha; 0, rms_slope) / cos^2 alpha.
  (The x-length of surface with tilt in d alpha is p(alpha) d alpha.)
* shadowing (Eq. 12 and the alternatives): each shadowing term's record in
  :mod:`hyde_bsdf.model.terms` carries its in-plane form ``g_plane``
  (:mod:`hyde_bsdf.model.shadowing`).  The Torrance-Sparrow V-groove function
  is itself a 2-D derivation, so it is exact in the plane:
  G = min(1, 2 cos(alpha) cos(theta_r) / cos(beta), 2 cos(alpha) cos(theta_i) / cos(beta)).
* :func:`brdf_specular` (Eqs. 6, 13): per unit x-length the facets with tilt
  in d alpha have length d alpha p(alpha)/cos(alpha) and intercept
  ``I0 cos(beta)`` each; they send it into d theta_r = 2 d alpha.  Dividing by
  the power ``I0 cos(theta_i)`` that falls on unit x-length, the fraction of
  incident power per radian of theta_r is
  ``p(alpha) cos(beta) G |r|^2 / (2 cos(alpha) cos(theta_i))``.  The 2-D BRDF
  f is defined, like Eq. 1, by that fraction = f cos(theta_r):

      f_s = p(alpha) G |r|^2 cos(beta) / (2 cos(theta_i) cos(theta_r) cos(alpha))     [1/rad]

  (PEC: |r|^2 = 1 for s-pol.)  In 3-D the Jacobian d omega_h/d omega_r =
  1/(4 cos beta) cancels the cos(beta); in 2-D the Jacobian is 1/2 and it
  stays.  Without shadowing and with every tilt (also back-facing ones) this
  integrates to exactly 1: cos(theta_i + alpha)/(cos alpha cos theta_i)
  = 1 - tan(theta_i) tan(alpha), whose p-average is 1.
* :func:`dhr_specular` (Eq. 14): rho_s(theta_i) = int_{-pi/2}^{pi/2} f_s cos(theta_r) d theta_r.
* :func:`brdf_diffuse` (Eq. 16): a Lambertian 2-D BRDF is a constant f_d, and
  int f_d cos(theta_r) d theta_r = 2 f_d, so energy conservation for a PEC
  gives f_d = (1 - rho_s(theta_i)) / 2.  Each diffuse term of :mod:`hyde_bsdf.model.terms` is
  the same function as on the 2-D surface (:mod:`hyde_bsdf.model.diffuse`), evaluated on the
  in-plane hemisphere :class:`PlaneHemisphere` (measure 2 instead of pi).
* :func:`brdf` (Eq. 17): f = f_s + f_d.
* :func:`mueller_sigma` (Eqs. 9-11, 17 in the plane): for a finite index the
  facet's Fresnel Mueller matrix at the local incidence angle beta (single
  bounce; in the plane of incidence the rotations of Eq. 9 are the identity)
  multiplies the specular term, [[A, B, 0, 0], [B, A, 0, 0], [0, 0, C, S],
  [0, 0, -S, C]] with A = (|r_s|^2+|r_p|^2)/2, B = (|r_s|^2-|r_p|^2)/2,
  C = Re(r_s r_p*), S = Im(r_s r_p*) (:func:`hyde_bsdf.model.fresnel.fresnel_mueller_terms`;
  a PEC has A = 1, B = 0, C = -1, S = 0).  The diffuse term of Eq. 16 is
  unpolarised: it adds (1 - rho_s^PEC(theta_i))/2 * A(beta) to M00 only, which is
  how the model depolarises.  Returned in sigma units, like the MoM's
  :attr:`hyde_bsdf.mom.MoMResult.mueller`.
* :func:`sigma_equivalent`: the model in the units of the MoM's Eq. 23.  The
  MoM's power balance is (1/(2 pi cos theta_i)) int sigma d theta_r, so
  sigma = 2 pi cos(theta_i) f cos(theta_r).  Note the cos(theta_r): sigma is
  power per unit scattering angle, a BRDF is radiance per irradiance.
"""
from __future__ import annotations

import math

import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.model.fresnel import fresnel_mueller_terms
from hyde_bsdf.model.index import Index
from hyde_bsdf.model.parameters import RMS_SLOPE
from hyde_bsdf.model.terms import check_pair, shadowing_term, term_arguments

__all__ = [
    "facet_angles",
    "facet_pdf",
    "brdf_specular",
    "dhr_specular",
    "PlaneHemisphere",
    "brdf_diffuse",
    "brdf",
    "sigma_equivalent",
    "lobe_energy_shares",
    "mueller_sigma",
]

_HALF_PI = 0.5 * math.pi


def _check(theta_i, theta_r, rms_slope):
    theta_i = np.asarray(theta_i, dtype=float)
    theta_r = np.asarray(theta_r, dtype=float)
    if not np.all(np.isfinite(theta_i)) or np.any(theta_i < 0) or np.any(theta_i >= _HALF_PI):
        raise UsageError("theta_i must be finite and in [0, pi/2) radians")
    if not np.all(np.isfinite(theta_r)) or np.any(np.abs(theta_r) > _HALF_PI):
        raise UsageError("theta_r must be finite signed angles in [-pi/2, pi/2] radians")
    rms_slope = RMS_SLOPE.check(rms_slope)
    return theta_i, theta_r, rms_slope


def facet_angles(theta_i, theta_r):
    """In-plane Eq. 7: facet tilt alpha = (theta_r - theta_i)/2 and local incidence beta = (theta_i + theta_r)/2 (radians)."""
    theta_i = np.asarray(theta_i, dtype=float)
    theta_r = np.asarray(theta_r, dtype=float)
    return 0.5 * (theta_r - theta_i), 0.5 * (theta_i + theta_r)


def facet_pdf(alpha, rms_slope):
    """1-D Eq. 8: pdf of the signed facet tilt alpha per radian, N(tan alpha; 0, rms_slope) / cos^2 alpha.

    Normalised: int_{-pi/2}^{pi/2} facet_pdf d alpha = 1 (x-length weighted).
    """
    alpha = np.asarray(alpha, dtype=float)
    t = np.tan(alpha)
    c = np.cos(alpha)
    return np.exp(-0.5 * (t / rms_slope) ** 2) / (math.sqrt(2.0 * math.pi) * rms_slope * c * c)


def _term_name(shadowing):
    """The record name of a shadowing argument: True is "vgroove", False "none" (this module's spelling)."""
    return "vgroove" if shadowing is True else "none" if shadowing is False else shadowing


def _shadowing(theta_i, theta_r, rms_slope, shadowing):
    """G in the plane of the chosen shadowing term (its record's ``g_plane``, :mod:`hyde_bsdf.model.terms`)."""
    return shadowing_term(_term_name(shadowing)).g_plane(theta_i, theta_r, rms_slope)


def brdf_specular(theta_i, theta_r, rms_slope, shadowing=True):
    """1-D counterpart of Eq. 13 for a PEC: f_s = p(alpha) G cos(beta) / (2 cos(ti) cos(tr) cos(alpha)), 1/rad.

    theta_i in [0, pi/2), theta_r signed in (-pi/2, pi/2) (radians; broadcast).
    ``shadowing``: a shadowing term of :mod:`hyde_bsdf.model.terms` (its in-plane ``g_plane``): True
    or "vgroove" (Eq. 12's V-groove G), "smith" (Smith's G of the 1-D Gaussian surface), False or
    "none" (G = 1 for front-facing facets).
    Returns 0 at |theta_r| = pi/2 (the observer at the horizon sees no facet).
    """
    theta_i, theta_r, rms_slope = _check(theta_i, theta_r, rms_slope)
    alpha, beta = facet_angles(theta_i, theta_r)
    g = _shadowing(theta_i, theta_r, rms_slope, shadowing)
    cr = np.cos(theta_r)
    with np.errstate(divide="ignore", invalid="ignore"):  # cos(theta_r) = 0 at the horizon: value set to 0 below
        f = facet_pdf(alpha, rms_slope) * g * np.cos(beta) / (2.0 * np.cos(theta_i) * cr * np.cos(alpha))
    return np.where(cr > 1e-12, f, 0.0)


def _theta_r_quadrature(n=2001):
    """Composite trapezoid nodes/weights over theta_r in [-pi/2, pi/2] (radians)."""
    t = np.linspace(-_HALF_PI, _HALF_PI, n)
    w = np.full(n, t[1] - t[0])
    w[[0, -1]] *= 0.5
    return t, w


def dhr_specular(theta_i, rms_slope, shadowing=True, n=4001):
    """1-D Eq. 14: rho_s(theta_i) = int_{-pi/2}^{pi/2} f_s(theta_i, theta_r) cos(theta_r) d theta_r.

    Trapezoid rule on ``n`` points (the integrand is continuous; its kinks from
    the min() in G limit the error to ~1e-6 at n = 4001).  theta_i: array, radians.
    """
    theta_i = np.asarray(theta_i, dtype=float)
    t, w = _theta_r_quadrature(n)
    f = brdf_specular(theta_i[..., None], t, rms_slope, shadowing)
    return (f * np.cos(t)) @ w


class PlaneHemisphere:
    """The hemisphere of :mod:`hyde_bsdf.model.diffuse` for the 1-D surface (scattering in the plane):
    ``one_minus(theta)`` = 1 - rho_s(|theta|) of :func:`dhr_specular` (Eq. 14 in the plane),
    ``measure`` = int_{-pi/2}^{pi/2} cos(theta) d theta = 2, and ``one_minus_avg`` =
    (1/2) int (1 - rho_s)^+ cos(theta) d theta (Gauss-Legendre, :data:`AVERAGE_NODES` nodes in
    |theta|): with it a diffuse term's in-plane integral is 1 - rho_s(theta_i), the 1-D Eq. 15."""
    measure = 2.0

    def __init__(self, rms_slope, shadowing=True):
        self.rms_slope, self.shadowing = rms_slope, shadowing

    def one_minus(self, theta):
        # |theta| = pi/2 (an observer on the horizon) is taken just above it: rho_s is continuous there
        t = np.minimum(np.abs(np.asarray(theta, dtype=float)), _THETA_MAX)
        return 1.0 - dhr_specular(t, self.rms_slope, self.shadowing)

    @property
    def one_minus_avg(self) -> float:
        x, w = np.polynomial.legendre.leggauss(AVERAGE_NODES)
        t = 0.25 * math.pi * (x + 1.0)
        return float(0.25 * math.pi * np.sum(w * np.maximum(self.one_minus(t), 0.0) * np.cos(t)))


#: Gauss-Legendre nodes in |theta| of :attr:`PlaneHemisphere.one_minus_avg` (rho_s has kinks: the
#: error falls as a power of the nodes; 1e-5 at 200, measured against 1600)
AVERAGE_NODES = 200
_THETA_MAX = _HALF_PI * (1.0 - 1e-12)


def brdf_diffuse(theta_i, rms_slope, shadowing=True, diffuse=True, theta_r=None, diffuse_reflectance=None):
    """1-D Eq. 16 for a PEC: the diffuse term ``diffuse`` (a diffuse record of :mod:`hyde_bsdf.model.terms`,
    True = "paper") on the in-plane hemisphere, 1/rad; the paper's is the Lambertian 2-D BRDF
    f_d = (1 - rho_s(theta_i)) / 2.  ``theta_r`` (signed, radians) is needed by a term that
    depends on it (the reciprocal one); it broadcasts against ``theta_i``.  ``diffuse_reflectance``:
    the albedo of the "lambertian" term (in the plane its f_d = albedo / 2)."""
    _, term = check_pair(_term_name(shadowing), diffuse)
    own = term_arguments(term, diffuse_reflectance=diffuse_reflectance)
    theta_i = np.asarray(theta_i, dtype=float)
    theta_r = theta_i if theta_r is None else np.asarray(theta_r, dtype=float)
    if not term.present:
        return np.zeros(np.broadcast(theta_i, theta_r).shape)
    return term.f00(PlaneHemisphere(rms_slope, shadowing), theta_i, theta_r, 1.0, **own)


def brdf(theta_i, theta_r, rms_slope, shadowing=True, diffuse=True, diffuse_reflectance=None):
    """1-D Eq. 17 for a PEC: f = f_s + f_d (1/rad); broadcasts theta_i against theta_r.

    ``diffuse``: a diffuse term of :mod:`hyde_bsdf.model.terms` (True = "paper", False = "none");
    ``diffuse_reflectance``: the "lambertian" term's albedo."""
    theta_i, theta_r, rms_slope = _check(theta_i, theta_r, rms_slope)
    check_pair(_term_name(shadowing), diffuse)
    f = brdf_specular(theta_i, theta_r, rms_slope, shadowing)
    return f + brdf_diffuse(theta_i, rms_slope, shadowing, diffuse, theta_r, diffuse_reflectance)


def sigma_equivalent(theta_i, theta_r, rms_slope, shadowing=True, diffuse=True):
    """The model in the MoM's Eq. 23 units: sigma = 2 pi cos(theta_i) f cos(theta_r).

    With it, (1/(2 pi cos ti)) int sigma d tr is the model's reflected/incident
    power, exactly as :attr:`hyde_bsdf.mom.MoMResult.power_balance`.
    theta_i [n_ti, 1] against theta_r [n_tr] (radians) gives [n_ti, n_tr].
    """
    theta_i = np.asarray(theta_i, dtype=float)
    theta_r = np.asarray(theta_r, dtype=float)
    f = brdf(theta_i, theta_r, rms_slope, shadowing, diffuse)
    return 2.0 * math.pi * np.cos(theta_i) * f * np.cos(theta_r)


def lobe_energy_shares(theta_i, theta_r, sigma_mom, rms_slope, level=0.01):
    """Energy the model's specular lobe misses against what the MoM puts outside that lobe.

    The lobe is where the model's specular term is at least ``level`` times its
    maximum over ``theta_r``.  Energies are fractions of the incident power,
    (1/(2 pi cos ti)) int sigma d tr on the ``theta_r`` grid given (radians,
    ascending, covering [-pi/2, pi/2]).

    Returns a dict of arrays over theta_i:
      ``model_missed`` = 1 - rho_s (what the specular lobe misses; the model's diffuse share),
      ``model_outside`` = model (specular + diffuse) energy outside the lobe,
      ``mom_outside`` = MoM energy outside the lobe,
      ``model_inside``, ``mom_inside``, ``mom_total``,
      ``specular_inside``, ``specular_outside`` (the model's specular term alone),
      ``mom_excess_inside`` = mom_inside - specular_inside: what the MoM puts inside the
      lobe beyond the single-reflection term (multiple scattering that stays near the lobe).
    """
    theta_i = np.atleast_1d(np.asarray(theta_i, dtype=float))
    theta_r = np.asarray(theta_r, dtype=float)
    sigma_mom = np.atleast_2d(sigma_mom)
    spec = sigma_equivalent(theta_i[:, None], theta_r, rms_slope, diffuse=False)
    total = sigma_equivalent(theta_i[:, None], theta_r, rms_slope, diffuse=True)
    inside = spec >= level * spec.max(axis=1, keepdims=True)
    scale = 1.0 / (2.0 * math.pi * np.cos(theta_i))

    def energy(s, mask):
        return np.trapezoid(np.where(mask, s, 0.0), theta_r, axis=1) * scale

    rho_s = dhr_specular(theta_i, rms_slope)
    mom_inside = energy(sigma_mom, inside)
    spec_inside = energy(spec, inside)
    return {
        "model_missed": 1.0 - rho_s,
        "specular_inside": spec_inside,
        "specular_outside": energy(spec, ~inside),
        "mom_excess_inside": mom_inside - spec_inside,
        "model_inside": energy(total, inside),
        "model_outside": energy(total, ~inside),
        "mom_inside": mom_inside,
        "mom_outside": energy(sigma_mom, ~inside),
        "mom_total": energy(sigma_mom, np.ones_like(inside)),
    }


def mueller_sigma(theta_i, theta_r, rms_slope, n=None, k=0.0, shadowing=True, diffuse=True, index=None):
    """In-plane Mueller elements of the 1-D model in the MoM's sigma units (Eqs. 9-11, 16, 17 in the plane).

    theta_i [n_ti, 1] against theta_r [n_tr] (radians; broadcast).  ``n``, ``k``: the index
    n + ik (the paper's eta = n - j k); ``n=None`` is the PEC; or ``index``, an
    :class:`~hyde_bsdf.model.index.Index`.  Returns a dict "M00", "M01", "M22",
    "M23": the facet Fresnel terms (A, B, C, S) at the local incidence angle
    beta = (theta_i + theta_r)/2 times the specular sigma, plus, in M00 only, the
    diffuse term (the paper's: (1 - rho_s(theta_i))/2) * A(beta) in sigma units.
    """
    index = Index.from_keywords(n, k, index=index, pec_if_missing=True)
    _, term = check_pair(_term_name(shadowing), diffuse)
    theta_i = np.asarray(theta_i, dtype=float)
    theta_r = np.asarray(theta_r, dtype=float)
    _, beta = facet_angles(theta_i, theta_r)
    A, B, C, S = fresnel_mueller_terms(np.clip(np.cos(beta), 0.0, 1.0), index)
    spec = sigma_equivalent(theta_i, theta_r, rms_slope, shadowing, diffuse=False)
    out = {"M00": spec * A, "M01": spec * B, "M22": spec * C, "M23": spec * S}
    if term.present:
        units = 2.0 * math.pi * np.cos(theta_i) * np.cos(theta_r)
        out["M00"] = out["M00"] + units * brdf_diffuse(theta_i, rms_slope, shadowing, term, theta_r) * A
    return out
