"""Facet angles from the macroscopic angles: the paper's Eqs. 7 and 10.

All functions take theta_i, theta_r (polar angles of the directions towards the
source and the observer) and phi = phi_r - phi_i (phi = pi: specular plane,
phi = 0: backscatter side), in radians, NumPy-broadcast.

The paper writes these with arccos and divisions that break down at the places
a user of the model meets first: backscatter (beta = 0), the specular peak
(alpha = 0), normal incidence (theta = 0).  Each function below states its
equation and the algebraically identical form it evaluates; the identities use
only 1 - cos(phi) = 2 sin^2(phi/2) and 1 + cos(phi) = 2 cos^2(phi/2), which
remove every cancellation.
"""
from __future__ import annotations

import numpy as np

__all__ = ["HORIZON_COS", "angle_trig", "half_angle_terms", "cos_alpha_beta", "rotation_terms"]

#: polar angle used in place of an exact 0 when the bases' orientation is needed:
#: the s/p bases at theta = 0 are defined as the limit at fixed azimuth.
_THETA_LIMIT = 1e-100
#: added to c^2 + s^2 in rotation_terms: selects gamma = 0 at exact backscatter.
_EPS = 1e-300


def half_angle_terms(sin_i, cos_i, sin_r, cos_r, cos_half_phi_sq):
    """Squared transverse and normal parts of omega_i + omega_r (= 2 cos(beta) h).

    With phi_i = 0, |omega_i + omega_r|^2 = hxy2 + hz^2 where
    ``hxy2 = (sin ti - sin tr)^2 + 4 sin ti sin tr cos^2(phi/2)`` and
    ``hz = cos ti + cos tr``; every term is >= 0 for directions above the horizon.
    """
    hxy2 = (sin_i - sin_r) ** 2 + 4.0 * sin_i * sin_r * cos_half_phi_sq
    hz = cos_i + cos_r
    return hxy2, hz


#: cos(theta) at or below which a direction is on the horizon (theta within ~1e-15 rad of 90 deg): there
#: cos is rounding, not geometry (pi/2 is no double: its cos comes out 1e-16), and Eq. 6's 1/(cos ti cos tr)
#: would give 1e31; at the horizon the matrix is 0, as below it (and as in Mitsuba's BSDFs)
HORIZON_COS = 1e-15


def angle_trig(theta_i, theta_r, phi):
    """sin/cos of theta_i, theta_r and of phi/2, computed once for Eqs. 7 and 10.

    theta is floored at 1e-100 so that the s/p bases at theta = 0 come out as the
    limit at fixed azimuth (see :func:`rotation_terms`); no other result changes.
    Returns (si, ci, sr, cr, sh, ch) with sh = sin(phi/2), ch = cos(phi/2).
    """
    # one tangent of the half angle per angle instead of a sine and a cosine:
    # sin = 2t/(1+t^2), cos = (1-t^2)/(1+t^2) are as well conditioned as np.sin/np.cos.
    out = []
    for angle in (np.maximum(theta_i, _THETA_LIMIT), np.maximum(theta_r, _THETA_LIMIT)):
        t = np.tan(0.5 * angle)
        inv = 1.0 / (1.0 + t * t)
        out += [2.0 * t * inv, (1.0 - t) * (1.0 + t) * inv]
    half = 0.5 * np.asarray(phi, dtype=float)
    return (*out, np.sin(half), np.cos(half))


def cos_alpha_beta(si, ci, sr, cr, sh, ch):
    """cos(alpha) and cos(beta) of paper Eq. 7, with tan^2(alpha).

    Eq. 7: cos(2 beta) = cos ti cos tr + sin ti sin tr cos phi and
    cos(alpha) = (cos ti + cos tr) / (2 cos beta).  Evaluated as
    cos(beta) = |omega_i + omega_r| / 2, cos(alpha) = hz / |omega_i + omega_r|,
    tan^2(alpha) = hxy2 / hz^2 (see :func:`half_angle_terms`), which are exact
    at alpha = 0 and beta = 0 where the arccos forms lose half their digits.
    Arguments are the sines and cosines from :func:`angle_trig`.

    Returns (cos_alpha, cos_beta, tan2_alpha).
    """
    hxy2, hz = half_angle_terms(si, ci, sr, cr, ch * ch)
    length = np.sqrt(hxy2 + hz * hz)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_alpha = hz / length
        tan2_alpha = hxy2 / (hz * hz)
    return cos_alpha, 0.5 * length, tan2_alpha


def rotation_terms(si, ci, sr, cr, sh, ch):
    """cos(2 gamma_i), sin(2 gamma_i), cos(2 gamma_r), sin(2 gamma_r) of paper Eq. 10.

    Eq. 10 gives cos(gamma_i) = (cos alpha - cos ti cos beta) / (sin ti sin beta)
    (similarly gamma_r): the angle between the macroscopic plane of incidence
    (reflection) and the facet's plane of scattering, unsigned.  Out of the
    specular plane the sign matters, so we use the signed form that follows from
    the bases of the paper's Eq. 9 (s = k x z / |k x z|, p = k x s; the facet's s
    = k_i x n / |k_i x n|), which spherical trigonometry reduces to

        sin(2 beta) cos(gamma_i) = sin(ti - tr) + 2 sin tr cos ti sin^2(phi/2)
        sin(2 beta) sin(gamma_i) = -sin tr sin phi
        sin(2 beta) cos(gamma_r) = sin(tr - ti) + 2 sin ti cos tr sin^2(phi/2)
        sin(2 beta) sin(gamma_r) = -sin ti sin phi

    (the first equals Eq. 10 times sin(2 beta); the common factor sin(2 beta)
    cancels in the double angles below, so no division by sin(beta) remains).
    The rotations enter the Mueller matrix only through 2 gamma.
    Arguments are the sines and cosines from :func:`angle_trig`.

    Singular cases, each with its limit:
    - theta = 0: the s/p basis is the limit at fixed azimuth; :func:`angle_trig`
      floors theta at 1e-100, which yields that limit to machine precision.
    - backscatter, omega_r = omega_i (beta = 0): both numerators vanish; the facet
      is seen at normal incidence, where r_p = -r_s and the Mueller matrix is
      continuous with gamma_i = gamma_r = 0, which the tiny EPS below selects
      (it is far below any non-zero c^2 + s^2, which is >= ~1e-200).
    """
    sin_diff = si * cr - ci * sr                 # sin(ti - tr); exactly 0 when ti == tr
    sh2 = sh * sh
    sin_phi = 2.0 * sh * ch
    out = []
    for c, s in ((sin_diff + 2.0 * sr * ci * sh2, -sr * sin_phi),
                 (-sin_diff + 2.0 * si * cr * sh2, -si * sin_phi)):
        cc, ss = c * c, s * s
        inv = 1.0 / (cc + ss + _EPS)
        out.append((cc - ss + _EPS) * inv)
        out.append(2.0 * c * s * inv)
    return tuple(out)
