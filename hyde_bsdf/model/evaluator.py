"""NumPy evaluator of the Hyde-Schmidt-Havrilla pBRDF, in the paper's angle formulation.

    F(theta_i, theta_r, phi) = F^s + F^d                                   (Eq. 5, 17)
    F^s = P(alpha) M(beta; eta) G / (4 cos ti cos tr cos alpha)            (Eq. 6, 13)
    F^d_00 = (1/pi) [1 - rho^{s,PEC}(theta_i)] M_00(beta; eta)             (Eq. 16, 17)
    or F^d_00 = diffuse_reflectance / pi                                  (a free Lambertian term)

with alpha, beta from Eq. 7, P Beckmann (Eq. 8), M the Mueller matrix of the
rotated Fresnel Jones matrix (Eqs. 9-11, all 16 elements), G the V-groove
shadowing (Eq. 12) or an alternative, rho^{s,PEC} the specular DHR (Eqs. 14-16)
read from the shipped table of :mod:`hyde_bsdf.model.dhr`.

Conventions (this interface)
----------------------------
- Angles in radians.  theta_i: polar angle of the direction towards the source,
  theta_r: towards the observer, phi = phi_r - phi_i.  phi = pi is the specular
  plane (forward scattering), as in the paper; phi = 0 the backscatter side.  For
  phi in [0, pi] this is the paper's |phi_r - phi_i|; phi in (pi, 2 pi) (or < 0)
  is the mirror-image geometry, whose Mueller matrix is D F D, D = diag(1,1,-1,-1).
- Index: the paper's eta = n - j kappa (e^{+j w t}), given as ``n``, ``k`` >= 0;
  Mitsuba's n + ik describes the same material with the same Mueller matrix.
- Stokes bases (the macroscopic s/p bases of Eq. 9): with phi_i = 0,
  omega_i = (sin ti, 0, cos ti), omega_r = (sin tr cos phi, sin tr sin phi, cos tr),
  propagation k_i = -omega_i, k_r = omega_r; for each wave s = k x z/|k x z| and
  p = k x s, so (s, p, k) is right-handed and s_i = s_r = +y in the specular plane.
  At theta = 0 the basis is the limit at fixed azimuth.
  S0 = |Es|^2+|Ep|^2, S1 = |Es|^2-|Ep|^2, S2 = 2 Re(Es Ep*), S3 = -2 Im(Es Ep*) in
  e^{+jwt} phasors (+2 Im(Es Ep*) in e^{-iwt}): a flat mirror at normal incidence
  is diag(1, 1, -1, -1).
- Roughness: ``rms_slope`` = sqrt(2) sigma_h / l (the paper's); Beckmann
  alpha = sqrt(2) rms_slope.  See :mod:`hyde_bsdf.model.roughness`.

Reciprocity: the specular part satisfies F^s(r -> i) = Q F^s(i -> r)^T Q with
Q = diag(1, 1, 1, -1) (tests check it).  The paper's diffuse term depends on
theta_i alone, so the published F is *not* reciprocal; ``diffuse="reciprocal"``
replaces it by (1 - rho(ti))(1 - rho(tr)) / (pi (1 - rho_avg)) M_00, symmetric in
i and r and with the same hemispherical integral 1 - rho(ti) (so the PEC energy
balance of Eq. 15 still closes), where rho_avg = 2 int rho(t) cos t sin t dt.
"""
from __future__ import annotations

import math

import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.model.checks import broadcast_named, real_array
from hyde_bsdf.model.dhr import DHRHemisphere
from hyde_bsdf.model.facet_geometry import HORIZON_COS, angle_trig, cos_alpha_beta, rotation_terms
from hyde_bsdf.model.fresnel import fresnel_mueller_terms
from hyde_bsdf.model.index import Index
from hyde_bsdf.model.jones_mueller import rotated_fresnel_mueller
from hyde_bsdf.model.roughness import check_rms_slope
from hyde_bsdf.model.slope_distribution import beckmann_P
from hyde_bsdf.model.terms import check_pair, diffuse_term, shadowing_term, term_arguments

__all__ = ["pbrdf", "specular_pbrdf", "diffuse_pbrdf"]


def _check_angles(name, value, hi):
    a = real_array(name, value, "radians")
    if hi is not None and np.any((a < 0.0) | (a > hi)):
        raise UsageError(f"{name} must be in [0, pi] radians (polar angle; > pi/2 is below the horizon)")
    return a


def _check_all_angles(theta_i, theta_r, phi):
    """The three angles checked (real, finite, polar angles in [0, pi]) and broadcastable."""
    theta_i = _check_angles("theta_i", theta_i, math.pi)
    theta_r = _check_angles("theta_r", theta_r, math.pi)
    phi = _check_angles("phi", phi, None)
    broadcast_named(theta_i=theta_i, theta_r=theta_r, phi=phi)
    return theta_i, theta_r, phi


def specular_pbrdf(theta_i, theta_r, phi, *, rms_slope, n=None, k=0.0, pec=False,
                   shadowing="vgroove", index=None):
    """F^s of Eqs. 6/13 (1/sr), shape broadcast(theta_i, theta_r, phi) + (4, 4).

    Same conventions and validation as :func:`pbrdf` (which adds the diffuse term).
    """
    s = check_rms_slope(rms_slope)
    index = Index.from_keywords(n, k, pec, index)
    term = shadowing_term(shadowing)
    theta_i, theta_r, phi = _check_all_angles(theta_i, theta_r, phi)
    return _evaluate(theta_i, theta_r, phi, s, index, term)


#: elements per block: every temporary of a block stays in the CPU cache, and the memory beyond the
#: result is a few blocks' worth whatever the number of directions.
_BLOCK = 8192


def _check_memory(size: int) -> None:
    """UsageError before the allocation when ``size`` directions need more than the available memory
    (:data:`~hyde_bsdf.resources.COSTS`: the result, 128 B per direction, and the blocks'
    temporaries); below 64 MiB nothing is read (the fits call this often)."""
    from hyde_bsdf.resources import COSTS, check_memory

    need = size * COSTS.pbrdf_bytes_per_direction
    if need > 64 * 2**20:
        check_memory(need, f"pbrdf of {size} directions ({COSTS.pbrdf_bytes_per_direction} B each, 128 B of it the "
                     "4x4 result)", "pass fewer directions in theta_i, theta_r, phi at once")


#: the last block's directions (their bytes) and geometry: a fit evaluates the same directions at every step with
#: other parameters, and the geometry depends on the directions alone (one entry, a block's worth of arrays)
_LAST_GEOMETRY = [None]


def _geometry(theta_i, theta_r, phi):
    """(angle_trig's sines and cosines, above the horizon, (cos alpha, cos beta, tan^2 alpha), Eq. 10's
    rotation terms) of one block of directions (1-D float arrays); the previous block's arrays (read-only)
    when its angles are these, bit for bit."""
    key = (theta_i.tobytes(), theta_r.tobytes(), phi.tobytes())
    last = _LAST_GEOMETRY[0]
    if last is not None and last[0] == key:
        return last[1]
    trig = angle_trig(theta_i, theta_r, phi)
    up = (trig[1] > HORIZON_COS) & (trig[3] > HORIZON_COS)     # at or below the horizon: F = 0
    geometry = (trig, up, cos_alpha_beta(*trig), rotation_terms(*trig))
    for a in (*trig, up, *geometry[2], *geometry[3]):
        a.flags.writeable = False
    _LAST_GEOMETRY[0] = (key, geometry)
    return geometry


def _evaluate(theta_i, theta_r, phi, s, index, shadowing, diffuse=None):
    """F^s (plus, with ``diffuse`` = (term, hemisphere, its parameters), F^d_00) for broadcast angles,
    an :class:`Index` and a shadowing record, :data:`_BLOCK` directions at a time: beyond the result the
    memory is bounded (broadcast angles are never expanded whole).  FloatingPointError, naming the
    first index, for a non-finite value.

    F has shape (..., 4, 4) but is a view of a (4, 4, ...) buffer, so that each
    element F[..., i, j] is contiguous (writing 16 strided planes costs more than
    the whole model); np.ascontiguousarray(F) gives the other layout.
    """
    ti, tr, ph = np.broadcast_arrays(theta_i, theta_r, phi)
    shape, size = ti.shape, ti.size
    _check_memory(size)
    buf = np.empty((4, 4, size))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        for lo in range(0, size, _BLOCK):
            sl = slice(lo, lo + _BLOCK)
            a, b = ti.flat[sl], tr.flat[sl]               # a copy of the block only
            trig, up, (cos_a, cos_b, tan2_a), rotation = _geometry(a, b, ph.flat[sl])
            si, ci, sr, cr, sh, ch = trig
            G = shadowing.g(cos_a, cos_b, ci, cr, s)
            # Eq. 6: F^s = P M G / (4 cos ti cos tr cos alpha)
            scale = beckmann_P(cos_a, tan2_a, s) * G / (4.0 * ci * cr * cos_a)
            scale = np.where(up, scale, 0.0)
            A, B, C, S = fresnel_mueller_terms(np.where(up, cos_b, 1.0), index)
            block = buf[:, :, sl]
            rotated_fresnel_mueller(A, B, C, S, *rotation, scale, block)
            if diffuse is not None:                       # Eq. 17: F^d_00 above the horizon
                term, hemisphere, own = diffuse
                block[0, 0] += np.where(up, term.f00(hemisphere, a, b, A, **own), 0.0)
            finite = np.isfinite(block).all(axis=(0, 1))
            if not finite.all():                          # never hand back NaN silently
                where = list(np.unravel_index(lo + int(np.argmin(finite)), shape))
                raise FloatingPointError(f"pbrdf produced a non-finite value at index {[int(w) for w in where]} "
                                         f"(rms_slope={s}, {index.text()}); please report it")
    return np.moveaxis(buf.reshape((4, 4) + shape), (0, 1), (-2, -1))


def diffuse_pbrdf(theta_i, theta_r, M00, rms_slope, mode="paper", shadowing="vgroove", diffuse_reflectance=None):
    """F^d_00 of the diffuse term ``mode`` (a name of :data:`hyde_bsdf.model.terms.DIFFUSE`, or
    True/False), e.g. Eqs. 16-17: (1/pi)(1 - rho^{s,PEC}(theta_i)) M00, with the DHR of ``shadowing``.

    ``M00`` is the facet Fresnel average M_00(beta; eta) (1 for a PEC).  With
    ``shadowing="none"`` rho can exceed 1 at grazing angles (Priest-Germer is
    unbounded); 1 - rho is then clipped at 0, which keeps F^d >= 0.
    ``diffuse_reflectance``: the albedo of ``mode="lambertian"`` (its own parameter).
    """
    term = diffuse_term(mode)
    if not term.present:
        return np.zeros(np.broadcast(theta_i, theta_r, M00).shape)
    own = term_arguments(term, diffuse_reflectance=diffuse_reflectance)
    f = term.f00(DHRHemisphere(shadowing_term(shadowing).name, rms_slope), theta_i, theta_r, M00, **own)
    return np.broadcast_to(f, np.broadcast(theta_i, theta_r, M00).shape).copy()  # Eq. 17 reads one direction


def pbrdf(theta_i, theta_r, phi, *, rms_slope, n=None, k=0.0, pec=False,
          shadowing="vgroove", diffuse=True, index=None, diffuse_reflectance=None):
    """The Hyde-Schmidt-Havrilla pBRDF Mueller matrix F (1/sr), paper Eq. 17.

    Parameters
    ----------
    theta_i, theta_r : array_like, radians in [0, pi]
        polar angles of the directions towards the source and the observer;
        directions at or below the horizon (cos <= 0) give an all-zero matrix.
    phi : array_like, radians
        phi_r - phi_i; pi = specular plane (see module docstring for bases).
    rms_slope : float in ``parameters.RMS_SLOPE`` ([1e-4, 50])
        the paper's roughness sqrt(2) sigma_h / l (Beckmann alpha / sqrt(2)).
    n, k : float >= 0
        the index n + ik (the paper writes the same material as eta = n - jk); or
        ``pec=True`` for a perfect conductor; or ``index`` instead, an
        :class:`~hyde_bsdf.model.index.Index` (``index.PEC`` for the PEC).
    shadowing : a shadowing term of :mod:`hyde_bsdf.model.terms`: "vgroove" (Eq. 12,
        the paper) | "smith" (exact Beckmann Smith) | "none"
    diffuse : a diffuse term of :mod:`hyde_bsdf.model.terms`: True / "paper" (Eq. 17) |
        "reciprocal" (symmetric variant) | False / "none" | "lambertian" (a free albedo,
        not the paper's); "reciprocal" needs a shadowing term
        (:func:`hyde_bsdf.model.terms.check_pair`).
        ``shadowing="none", diffuse=False`` is the Priest-Germer pBRDF (Fig. 4).
        The paper's diffuse term uses the DHR of the same shadowing model.
    diffuse_reflectance : float in ``parameters.DIFFUSE_REFLECTANCE`` ([0, 1]), only with
        ``diffuse="lambertian"``: its albedo, F_00 += diffuse_reflectance / pi (default 0.5,
        Mitsuba's).

    Returns
    -------
    ndarray of shape broadcast(theta_i, theta_r, phi) + (4, 4), in the paper's
    s/p Stokes bases; ``F @ S_in * cos(theta_i) * d omega_i`` is the reflected
    Stokes radiance for incident Stokes radiance S_in.

    Raises
    ------
    TypeError for a value of the wrong kind (complex, string or boolean angles or
    parameters, an array rms_slope/n/k, ``pec`` other than True/False); ValueError for a
    value out of range, non-finite, or angles that do not broadcast together.  Each
    message names the parameter and what it accepts.
    """
    s = check_rms_slope(rms_slope)
    index = Index.from_keywords(n, k, pec, index)
    shadow, term = check_pair(shadowing, diffuse)     # the rules of model/terms.py
    own = term_arguments(term, diffuse_reflectance=diffuse_reflectance)
    theta_i, theta_r, phi = _check_all_angles(theta_i, theta_r, phi)
    diffuse = (term, DHRHemisphere(shadow.name, s), own) if term.present else None
    return _evaluate(theta_i, theta_r, phi, s, index, shadow, diffuse)
