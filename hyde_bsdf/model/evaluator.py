"""NumPy evaluator of the Hyde-Schmidt-Havrilla pBRDF, in the paper's angle formulation.

    F(theta_i, theta_r, phi) = F^s + F^d                                   (Eq. 5, 17)
    F^s = P(alpha) M(beta; eta) G / (4 cos ti cos tr cos alpha)            (Eq. 6, 13)
    F^d_00 = (1/pi) [1 - rho^{s,PEC}(theta_i)] M_00(beta; eta)             (Eq. 16, 17)

with alpha, beta from Eq. 7, P Beckmann (Eq. 8), M the Mueller matrix of the
rotated Fresnel Jones matrix (Eqs. 9-11, all 16 elements), G the V-groove
shadowing (Eq. 12) or an alternative, rho^{s,PEC} the specular DHR (Eqs. 14-16)
read from the cached table of :mod:`hyde_bsdf.model.dhr`.

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

from hyde_bsdf.errors import UsageError, shorten

from hyde_bsdf.model.checks import broadcast_named, check_bool, real_array
from hyde_bsdf.model.dhr import load_table, x_of_theta
from hyde_bsdf.model.facet_geometry import angle_trig, cos_alpha_beta, rotation_terms
from hyde_bsdf.model.fresnel import fresnel_mueller_terms
from hyde_bsdf.model.jones_mueller import rotated_fresnel_mueller
from hyde_bsdf.model.parameters import INDEX_MIN, K, N, RMS_SLOPE
from hyde_bsdf.model.roughness import check_rms_slope
from hyde_bsdf.model.shadowing import check_shadowing, visibility
from hyde_bsdf.model.slope_distribution import beckmann_P

__all__ = ["pbrdf", "specular_pbrdf", "diffuse_pbrdf", "DIFFUSE", "check_diffuse"]

DIFFUSE = ("paper", "reciprocal", "none")
RMS_SLOPE_RANGE = RMS_SLOPE.bounds      # hyde_bsdf.model.parameters, the one definition
INDEX_MAX = N.hi


def _check_angles(name, value, hi):
    a = real_array(name, value, "radians")
    if hi is not None and np.any((a < 0.0) | (a > hi)):
        raise UsageError(f"{name} must be in [0, pi] radians (polar angle; > pi/2 is below the horizon)")
    return a


def _check_index(n, k, pec):
    if check_bool("pec", pec):
        if n is not None:
            raise UsageError("give either n (and k) or pec=True, not both")
        return None, None
    if n is None:
        raise UsageError("n is required (eta = n - jk) unless pec=True")
    out = [rng.check(v) for rng, v in ((N, n), (K, k))]
    if math.hypot(*out) < INDEX_MIN:       # eta^2 would underflow in the Fresnel terms
        raise UsageError(f"n and k: |eta| = sqrt(n^2 + k^2) must be >= {INDEX_MIN:g}, got n={out[0]!r}, k={out[1]!r}")
    return out


def _check_all_angles(theta_i, theta_r, phi):
    """The three angles checked (real, finite, polar angles in [0, pi]) and broadcastable."""
    theta_i = _check_angles("theta_i", theta_i, math.pi)
    theta_r = _check_angles("theta_r", theta_r, math.pi)
    phi = _check_angles("phi", phi, None)
    broadcast_named(theta_i=theta_i, theta_r=theta_r, phi=phi)
    return theta_i, theta_r, phi


def check_diffuse(diffuse) -> str:
    """The diffuse mode, one of :data:`DIFFUSE`, of ``pbrdf``'s ``diffuse`` argument (True is
    "paper", False or None "none"); UsageError otherwise (the fit checks its option with it too)."""
    if diffuse is True:
        return "paper"
    if diffuse is False or diffuse is None:
        return "none"
    if isinstance(diffuse, str) and diffuse in DIFFUSE:
        return diffuse
    raise UsageError(f"diffuse must be True, False or one of {DIFFUSE}, got {shorten(diffuse)}")


def specular_pbrdf(theta_i, theta_r, phi, *, rms_slope, n=None, k=0.0, pec=False,
                   shadowing="vgroove"):
    """F^s of Eqs. 6/13 (1/sr), shape broadcast(theta_i, theta_r, phi) + (4, 4).

    Same conventions and validation as :func:`pbrdf` (which adds the diffuse term).
    """
    s = check_rms_slope(rms_slope)
    nk = _check_index(n, k, pec)
    check_shadowing(shadowing)
    theta_i, theta_r, phi = _check_all_angles(theta_i, theta_r, phi)
    return _specular(theta_i, theta_r, phi, s, nk, pec, shadowing)[0]


#: elements per block: every temporary of a block stays in the CPU cache.
_BLOCK = 8192


def _specular(theta_i, theta_r, phi, s, nk, pec, shadowing):
    """F^s and M_00(beta) for broadcast angles; returns (F, M00, above).

    F has shape (..., 4, 4) but is a view of a (4, 4, ...) buffer, so that each
    element F[..., i, j] is contiguous (writing 16 strided planes costs more than
    the whole model); np.ascontiguousarray(F) gives the other layout.
    """
    ti, tr, ph = np.broadcast_arrays(theta_i, theta_r, phi)
    shape = ti.shape
    ti, tr, ph = ti.ravel(), tr.ravel(), ph.ravel()
    size = ti.size
    buf = np.empty((4, 4, size))
    M00 = np.empty(size)
    above = np.empty(size, bool)
    n, k = nk or (0.0, 0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        for lo in range(0, size, _BLOCK):
            sl = slice(lo, lo + _BLOCK)
            si, ci, sr, cr, sh, ch = trig = angle_trig(ti[sl], tr[sl], ph[sl])
            up = (ci > 0.0) & (cr > 0.0)                       # below the horizon: F = 0
            cos_a, cos_b, tan2_a = cos_alpha_beta(*trig)
            G = visibility(shadowing, cos_a, cos_b, ci, cr, s)
            # Eq. 6: F^s = P M G / (4 cos ti cos tr cos alpha)
            scale = beckmann_P(cos_a, tan2_a, s) * G / (4.0 * ci * cr * cos_a)
            scale = np.where(up, scale, 0.0)
            A, B, C, S = fresnel_mueller_terms(np.where(up, cos_b, 1.0), n, k, pec=pec)
            rotated_fresnel_mueller(A, B, C, S, *rotation_terms(*trig), scale, buf[:, :, sl])
            M00[sl] = A
            above[sl] = up
    F = np.moveaxis(buf.reshape((4, 4) + shape), (0, 1), (-2, -1))
    return F, M00.reshape(shape), above.reshape(shape)


def diffuse_pbrdf(theta_i, theta_r, M00, rms_slope, mode="paper", shadowing="vgroove"):
    """F^d_00 of Eqs. 16-17: (1/pi)(1 - rho^{s,PEC}(theta_i)) M00, or its reciprocal variant.

    ``M00`` is the facet Fresnel average M_00(beta; eta) (1 for a PEC).  With
    ``shadowing="none"`` rho can exceed 1 at grazing angles (Priest-Germer is
    unbounded); 1 - rho is then clipped at 0, which keeps F^d >= 0.
    """
    table = load_table(shadowing)
    grid, rho_x = table.x_slice(float(rms_slope))
    one_minus_x = 1.0 - rho_x
    # interpolate, then clip (rho > 1 only without shadowing; the plugin's texture does the same)
    one_minus = lambda t: np.maximum(np.interp(x_of_theta(t), grid, one_minus_x), 0.0)
    if mode == "paper":
        return one_minus(theta_i) * M00 / math.pi
    # 1 - rho_avg = int (1 - rho) d(cos^2 theta) = int_0^1 4 (1-x)^3 (1 - rho(x)) dx, from the very
    # samples used above, so that the hemispherical integral is exactly 1 - rho(theta_i)
    avg = float(np.trapezoid(4.0 * (1.0 - grid) ** 3 * np.maximum(one_minus_x, 0.0), grid))
    if avg <= 0.0:    # rho = 1 everywhere (a mirror-smooth surface): no multiple scattering
        return np.zeros(np.broadcast(theta_i, theta_r, M00).shape)
    return one_minus(theta_i) * one_minus(theta_r) * M00 / (math.pi * avg)


def pbrdf(theta_i, theta_r, phi, *, rms_slope, n=None, k=0.0, pec=False,
          shadowing="vgroove", diffuse=True):
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
        the complex index eta = n - jk; or ``pec=True`` for a perfect conductor.
    shadowing : "vgroove" (Eq. 12, the paper) | "smith" (exact Beckmann Smith) | "none"
    diffuse : True / "paper" (Eq. 17) | "reciprocal" (symmetric variant) | False / "none"
        ``shadowing="none", diffuse=False`` is the Priest-Germer pBRDF (Fig. 4).
        The diffuse term uses the DHR of the same shadowing model.

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
    nk = _check_index(n, k, pec)
    mode = check_diffuse(diffuse)
    check_shadowing(shadowing)
    if mode == "reciprocal" and shadowing == "none":
        # without shadowing rho^{s,PEC} exceeds 1 at grazing incidence, so the reciprocal
        # normalisation 1 - rho_avg is not positive (the plugin refuses the same pair)
        raise UsageError("diffuse='reciprocal' needs shadowing='vgroove' or 'smith'; with shadowing='none' "
                         "the specular DHR exceeds 1 and (1 - rho_avg) is not positive")
    theta_i, theta_r, phi = _check_all_angles(theta_i, theta_r, phi)
    out, A, above = _specular(theta_i, theta_r, phi, s, nk, pec, shadowing)
    if mode != "none":
        ti, tr = np.broadcast_arrays(theta_i, theta_r)
        out[..., 0, 0] += np.where(above, diffuse_pbrdf(ti, tr, A, s, mode, shadowing), 0.0)
    if not np.isfinite(out).all():   # never hand back NaN silently
        bad = np.argwhere((~np.isfinite(out.reshape(out.shape[:-2] + (16,)))).any(-1))[:1]
        where = bad[0].tolist() if bad.size else []
        raise FloatingPointError(f"pbrdf produced a non-finite value at index {where} "
                                 f"(rms_slope={s}, n={n}, k={k}, pec={pec}); please report it")
    return out
