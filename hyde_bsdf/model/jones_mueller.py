"""The facet's Jones matrix (paper Eq. 9) and its Mueller matrix (Eq. 11, all 16 elements).

Stokes convention (the paper's, Eq. 11): S0 = |Es|^2 + |Ep|^2,
S1 = |Es|^2 - |Ep|^2, S2 = 2 Re(Es Ep*), S3 = -2 Im(Es Ep*) for e^{+jwt} phasors
(the same numbers as S3 = +2 Im(Es Ep*) for e^{-iwt} phasors and eta = n + ik).
"""
from __future__ import annotations

import numpy as np

__all__ = ["jones_matrix", "jones_to_mueller", "rotated_fresnel_mueller"]


def jones_matrix(rs, rp, gamma_i, gamma_r):
    """T = R(gamma_r) diag(rs, rp) R'(gamma_i), paper Eq. 9.

    ``T[..., 0, 0] = T_ss, T[..., 0, 1] = T_ps, T[..., 1, 0] = T_sp, T[..., 1, 1] = T_pp``
    so that (E_r^s, E_r^p) = T (E_i^s, E_i^p).  gamma_i, gamma_r are signed
    (see :func:`hyde_bsdf.model.facet_geometry.rotation_terms`).
    """
    ci, si = np.cos(gamma_i), np.sin(gamma_i)
    cr, sr = np.cos(gamma_r), np.sin(gamma_r)
    out_rot = np.stack([np.stack([cr, sr], -1), np.stack([-sr, cr], -1)], -2)
    in_rot = np.stack([np.stack([ci, -si], -1), np.stack([si, ci], -1)], -2)
    rs, rp = np.broadcast_arrays(np.asarray(rs, complex), np.asarray(rp, complex))
    fres = np.zeros(rs.shape + (2, 2), complex)
    fres[..., 0, 0] = rs
    fres[..., 1, 1] = rp
    return out_rot @ fres @ in_rot


def jones_to_mueller(T):
    """Mueller matrix of a Jones matrix, all 16 elements (Eq. 11 generalised out of plane).

    With a = T_ss, b = T_ps, c = T_sp, d = T_pp (Eq. 9), M = A (T kron T*) A^-1 for
    the Stokes convention above; written out, e.g. M_00 = (|a|^2+|b|^2+|c|^2+|d|^2)/2,
    M_22 = Re(a d* + b* c), M_23 = Im(a d* + b* c): the in-plane entries equal Eq. 11's
    (which carries the overall factor 1/2 in front of its matrix).
    """
    T = np.asarray(T, complex)
    a, b, c, d = T[..., 0, 0], T[..., 0, 1], T[..., 1, 0], T[..., 1, 1]
    aa, bb, cc, dd = (abs(x) ** 2 for x in (a, b, c, d))
    ab, cd = a * np.conj(b), c * np.conj(d)
    ac, bd = a * np.conj(c), b * np.conj(d)
    ad, bc = a * np.conj(d), np.conj(b) * c
    M = np.empty(T.shape[:-2] + (4, 4))
    M[..., 0, :] = np.stack([(aa + bb + cc + dd) / 2, (aa - bb + cc - dd) / 2, (ab + cd).real, (ab + cd).imag], -1)
    M[..., 1, :] = np.stack([(aa + bb - cc - dd) / 2, (aa - bb - cc + dd) / 2, (ab - cd).real, (ab - cd).imag], -1)
    M[..., 2, :] = np.stack([(ac + bd).real, (ac - bd).real, (ad + bc).real, (ad + bc).imag], -1)
    M[..., 3, :] = np.stack([-(ac + bd).imag, -(ac - bd).imag, bc.imag - ad.imag, ad.real - bc.real], -1)
    return M


def rotated_fresnel_mueller(A, B, C, S, cos2gi, sin2gi, cos2gr, sin2gr, scale, out):
    """scale * Mueller(Eq. 9's T), written into ``out[4, 4, ...]`` (Mueller indices first).

    Because T is a product (rotation, Fresnel, rotation) and the Jones->Mueller map
    is multiplicative, Mueller(T) = L(-2 gamma_r) M_F L(2 gamma_i) with M_F the
    in-plane Fresnel Mueller matrix [[A,B,0,0],[B,A,0,0],[0,0,C,S],[0,0,-S,C]]
    and L the Stokes rotation.  This is :func:`jones_to_mueller` of
    :func:`jones_matrix` (tests check the identity) at a tenth of the cost.
    """
    sA, sB, sC, sS = scale * A, scale * B, scale * C, scale * S
    out[0, 0] = sA
    out[0, 1] = sB * cos2gi
    out[0, 2] = -sB * sin2gi
    out[0, 3] = 0.0
    out[1, 0] = cos2gr * sB
    out[2, 0] = -sin2gr * sB
    out[3, 0] = 0.0
    Aci, Asi, Cci, Csi = sA * cos2gi, sA * sin2gi, sC * cos2gi, sC * sin2gi
    out[1, 1] = cos2gr * Aci + sin2gr * Csi
    out[1, 2] = -cos2gr * Asi + sin2gr * Cci
    out[1, 3] = sin2gr * sS
    out[2, 1] = -sin2gr * Aci + cos2gr * Csi
    out[2, 2] = sin2gr * Asi + cos2gr * Cci
    out[2, 3] = cos2gr * sS
    out[3, 1] = -sS * sin2gi
    out[3, 2] = -sS * cos2gi
    out[3, 3] = sC
    return out
