"""Fresnel reflection coefficients of a facet (used in the paper's Eq. 9).

Convention at this interface: the index is the paper's eta = n - j*kappa with
e^{+j w t} phasors.  Internally the square root is taken in the equivalent
e^{-i w t} form (n + i kappa, principal branch, Im >= 0: a wave that decays into
the material) and the result conjugated back, which picks the decaying branch
for every n, kappa >= 0, including kappa = 0 with n < sin(beta) (total
internal reflection-like evanescence).

Signs: r_s and r_p refer to right-handed (s, p, k) bases for both the incident
and the reflected wave with a shared s vector, so a perfect conductor at
normal incidence has r_s = -1, r_p = +1 (a mirror flips the handedness of the
transverse basis; its Mueller matrix is diag(1, 1, -1, -1)).
"""
from __future__ import annotations

import numpy as np

__all__ = ["fresnel_rs_rp", "fresnel_mueller_terms"]


def fresnel_rs_rp(cos_beta, n, k):
    """Complex Fresnel amplitude coefficients r_s, r_p at local incidence angle beta.

    Parameters
    ----------
    cos_beta : array_like, in [0, 1]
        cosine of the angle between the incident direction and the facet normal.
    n, k : float >= 0
        the paper's eta = n - j*k (Born & Wolf Eqs. 1.5.20-21 with a complex index).

    Returns
    -------
    rs, rp : complex ndarrays, in the paper's e^{+j w t} convention.
    """
    c = np.asarray(cos_beta, dtype=float)
    eta2 = complex(n, k) ** 2            # e^{-iwt} form n + ik; conjugated below
    sin2 = 1.0 - c * c
    w = np.sqrt(eta2 - sin2)             # principal branch: Im(w) >= 0, decaying
    rs = (c - w) / (c + w)
    rp = (eta2 * c - w) / (eta2 * c + w)
    return np.conj(rs), np.conj(rp)


def fresnel_mueller_terms(cos_beta, index):
    """The four distinct entries of a facet's Fresnel Mueller matrix.

    The in-plane Mueller matrix of the facet (paper Eq. 11 with T = diag(r_s, r_p))
    is ``[[A, B, 0, 0], [B, A, 0, 0], [0, 0, C, S], [0, 0, -S, C]]`` with
    A = (|r_s|^2+|r_p|^2)/2, B = (|r_s|^2-|r_p|^2)/2, C = Re(r_s r_p*),
    S = Im(r_s r_p*) (e^{+jwt} phasors; Stokes S3 = -2 Im(E_s E_p*)).

    ``index``: an :class:`hyde_bsdf.model.index.Index` (n + ik, the paper's eta = n - jk).
    Returns (A, B, C, S) as float arrays broadcast like ``cos_beta``.  The perfect conductor
    (``index.is_pec``, k -> infinity) has r_s = -1, r_p = 1: A = 1, B = 0, C = -1, S = 0.
    """
    c = np.asarray(cos_beta, dtype=float)
    if index.is_pec:
        one = np.ones_like(c)
        zero = np.zeros_like(c)
        return one, zero, -one, zero
    rs, rp = fresnel_rs_rp(c, index.n, index.k)
    rs2 = rs.real ** 2 + rs.imag ** 2
    rp2 = rp.real ** 2 + rp.imag ** 2
    x = rs * np.conj(rp)
    return 0.5 * (rs2 + rp2), 0.5 * (rs2 - rp2), x.real, x.imag
