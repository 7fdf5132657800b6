"""Method-of-moments (MoM) reference solver for a random rough PEC surface (paper Section 3).

What it computes
----------------
The paper's Fig. 6 reference: a 1-D random rough, perfectly conducting surface
``y = f(x)`` (invariant along z), lit by an s-polarised (TM_z, E along z) plane
wave, solved exactly by the electric-field integral equation (EFIE, Eq. 18)
with pulse basis functions and point matching (Eqs. 19-20).  The long surface
is cut into ``M`` partitions; each partition's induced current is windowed by
the Gaussian taper of Eq. 22, radiated to the far field (Eq. 21), and the
partitions' far-field powers are averaged incoherently and normalised by the
taper's effective length (Eq. 23).

Geometry and conventions
------------------------
* Units: lengths in wavelengths (lambda = 1, k = 2*pi); the free-space
  impedance Z0 is factored out of the current (we solve for Z0*J), so no
  quantity depends on it.
* ``e^{+j w t}`` phasors (the paper's), so outgoing waves go as ``e^{-j k rho}``.
* Mean surface along x, y up.  The incident wave (Eq. 18) is
  ``E_i = exp(-j k (x sin ti - y cos ti))``: it travels towards +x and down, so
  its source sits at the signed angle ``-theta_i``.
* Far-field direction ``theta_r`` is signed, measured from +y towards +x:
  ``theta_r = +theta_i`` is the specular direction (forward side),
  ``theta_r < 0`` the backscatter side.  This matches the project convention
  "signed theta_r measured on the forward side" (phi = pi for theta_r >= 0).
* Angles: the public entry point :func:`scatter` takes degrees (as its
  argument names say); everything inside and every result attribute is in
  radians, except the ``*_deg`` copies provided for convenience.

Normalisation (Eq. 23) and the power balance
--------------------------------------------
With unit incident amplitude, the 2-D far field of one partition is
``E = Z0/(2 sqrt(rho lambda)) e^{-j(k rho - pi/4)} F``, ``F = sum_n alpha_n
W(x_n) int_{C_n} exp(j k (x' sin tr + y' cos tr)) dC'`` (Eq. 21), so
``2 pi rho |E|^2 = (pi/(2 lambda)) |Z0 F|^2``.  Eq. 23 divides the partition
average of this 2-D radar cross section by the taper's effective length
``w sqrt(pi/2) = int W(x)^2 dx``:

    sigma(theta_r) = 1/(w sqrt(pi/2)) * 1/M * sum_m (pi/2) |Z0 F_m(theta_r)|^2 .

The incident power on an effective length L_eff of mean surface is
``L_eff cos(theta_i) |E_i|^2/(2 Z0)`` and the scattered power per radian is
``rho |E|^2/(2 Z0)``, hence the reflected-over-incident power is

    power_balance_nominal(theta_i) = 1/(2 pi cos theta_i) * int_{-pi/2}^{pi/2} sigma(theta_r) dtheta_r ,

which is 1 for a PEC (no absorption).  For a flat plate the physical-optics
current ``Z0 J = 2 cos(ti) e^{-j k x sin ti}`` gives exactly 1, which is the
flat-plate test.  On a rough surface a finite sample is tilted at random: a
partition whose ends differ in height intercepts cos(ti + tilt)/cos(ti) of the
nominal power.  That is sampling noise, not a MoM error, and near grazing it
averages away slowly (about tan(ti) sqrt(2) sigma_h / (w sqrt(pi/2) sqrt(M)),
~1 % at 75 deg for the Fig. 6 case).  ``power_balance`` therefore divides the
reflected power by the incident power that actually falls on the windowed
partitions, sum_m int W_m^2 (cos ti + f' sin ti) dx (:func:`incident_flux`),
which is the nominal one for a flat plate and on average; this is the check of
the MoM's energy conservation.  The far-field powers are integrated on an
internal grid (:func:`power_grid`, steps of min(0.25 deg, 1/(k w))), whatever
``theta_r_deg`` the caller asks for.

``sigma`` contains both the coherent part (``|<F>|^2``, the specular spike of a
smooth surface) and the incoherent part; ``sigma_coherent`` and
``sigma_incoherent`` split them (the coherent part is the unbiased estimate
(M |mean F|^2 - mean |F|^2)/(M - 1), noisy where it is near 0).

Where MoM fails (warnings and errors)
-------------------------------------
:class:`MoMAccuracyWarning` is issued, with the reason, when
* fewer than 5 points per wavelength (or fewer than 5 per correlation length)
  sample the surface: the pulse currents no longer resolve the field; below 2
  points per wavelength a ``ValueError`` is raised instead;
* the taper is too narrow for the incidence angle (grazing): Thorsos'
  parameter ``(1 + 2 tan^2 ti)/(k w cos ti)^2`` above 0.02 or the taper's
  angular spectrum (3 standard deviations, ``3/(k w)`` in sin(theta)) crossing
  grazing.  The windowed current then no longer represents a plane-wave
  illumination and the power balance drifts off 1;
* partitions are too short for the correlation length (partition shorter than
  10 correlation lengths): a partition then holds too few independent facets
  and the surface is no longer a stationary random sample at the partition
  scale;
* the taper is too wide for the partition (w > L_p/3): the truncated ends of
  the partition are not windowed away and edge diffraction leaks in.

Parallelism
-----------
Partitions are independent tasks submitted to a :class:`concurrent.futures.Executor`
(a process pool by default; ``client.get_executor()`` of a dask.distributed
client works the same way).  Each worker fills its matrix, factors it once
with :func:`scipy.linalg.lu_factor` and solves all incidence angles as
right-hand sides; no worker holds more than one partition's matrix.
"""
from __future__ import annotations

import concurrent.futures as cf
import ctypes
import math
import multiprocessing
import os
import sys
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.special

__all__ = [
    "scatter",
    "MoMResult",
    "MoMAccuracyWarning",
    "SerialExecutor",
    "process_pool",
    "gaussian_surface",
    "moment_matrix",
    "incident_field",
    "far_field",
    "incident_flux",
    "taper",
    "check_sampling",
    "check_taper",
    "check_partition",
    "power_grid",
]

K0 = 2.0 * math.pi  # wavenumber in units of 1/lambda
EULER_GAMMA_EXP = math.exp(np.euler_gamma)  # gamma = 1.781... of the self term
#: Gauss-Legendre nodes/weights on [-1, 1] for near-neighbour and self integrals
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
#: Thorsos' taper parameter above which the taper is "too narrow" for theta_i
THORSOS_LIMIT = 0.02


class MoMAccuracyWarning(UserWarning):
    """The MoM set-up is outside the range where its answer can be trusted."""


# ---------------------------------------------------------------------------
# Surface (Fung & Chen 1985 spectral method)
# ---------------------------------------------------------------------------

def gaussian_surface(length_wl, n_points, rms_height_wl, corr_length_wl, seed=0):
    """Gaussian random surface with Gaussian correlation, by spectral filtering of white noise.

    The surface (Fung & Chen, JOSA A 2, 2274 (1985), the paper's Ref. 43) is
    ``f(x) = sum_j a_j exp(i k_j x)`` on the periodic interval [0, length), with
    ``k_j = 2 pi j / length``, Hermitian ``a_{-j} = conj(a_j)`` and independent
    complex Gaussian ``a_j`` of variance ``W(k_j) dk / (2 pi)``, where
    ``W(k) = sigma_h^2 ell sqrt(pi) exp(-k^2 ell^2 / 4)`` is the power spectrum
    of the correlation ``C(x) = sigma_h^2 exp(-x^2/ell^2)``.  The sum is
    truncated where W < 1e-16 W(0) (k ell > 12), so the random draws depend only
    on (length, ell, seed) and the same realisation is sampled exactly at any
    ``n_points`` (what the convergence study needs).

    Parameters
    ----------
    length_wl : float, surface length in wavelengths.
    n_points : int, samples at x_n = (n + 1/2) length / n_points.
    rms_height_wl, corr_length_wl : float, sigma_h and ell in wavelengths
        (sigma_h = 0 gives a flat surface).
    seed : int, seed of :func:`numpy.random.default_rng`.

    Returns
    -------
    x, f, dfdx : ndarray [n_points] -- abscissae, heights (wavelengths) and the
        exact slope of the band-limited surface.
    """
    length_wl = float(length_wl)
    n_points = int(n_points)
    dx = length_wl / n_points
    x = (np.arange(n_points) + 0.5) * dx
    if rms_height_wl == 0.0:
        return x, np.zeros(n_points), np.zeros(n_points)
    dk = 2.0 * math.pi / length_wl
    j_max = int(math.ceil(12.0 / corr_length_wl / dk))
    if 2 * j_max >= n_points:
        raise ValueError(
            f"n_points={n_points} cannot resolve a surface with corr_length_wl={corr_length_wl}: "
            f"need more than {2 * j_max} samples over {length_wl} wavelengths")
    rng = np.random.default_rng(seed)
    g = rng.standard_normal((j_max + 1, 2))
    kj = dk * np.arange(j_max + 1)
    spectrum = rms_height_wl**2 * corr_length_wl * math.sqrt(math.pi) * np.exp(-(kj * corr_length_wl) ** 2 / 4)
    amp = np.sqrt(spectrum * dk / (2.0 * math.pi))
    a = amp * (g[:, 0] + 1j * g[:, 1]) / math.sqrt(2.0)
    a[0] = amp[0] * g[0, 0]  # the mean term is real
    a = a * np.exp(1j * kj * dx / 2)  # shift the grid to the cell centres (n + 1/2) dx
    # irfft(X, n)[m] = (1/n) [X_0 + 2 Re sum_j X_j e^{2 pi i j m/n}], so X_j = n a_j (j>=1), X_0 = n a_0
    X = np.zeros(n_points // 2 + 1, dtype=complex)
    X[: j_max + 1] = n_points * a
    f = np.fft.irfft(X, n=n_points)
    X[: j_max + 1] *= 1j * kj
    dfdx = np.fft.irfft(X, n=n_points)
    return x, f, dfdx


# ---------------------------------------------------------------------------
# Eqs. 18-20: the EFIE moment matrix and the incident field
# ---------------------------------------------------------------------------

def _sinc(a):
    """sin(a)/a for real arrays; a Taylor polynomial where |a| <= 1.2 (error < 1e-7), NumPy's sinc beyond."""
    if a.size and np.max(np.abs(a)) > 1.2:
        return np.sinc(a / math.pi)
    a2 = a * a
    # 1 - a^2/6 + a^4/120 - a^6/5040 + a^8/362880
    out = a2 * (1.0 / 362880.0)
    out -= 1.0 / 5040.0
    out *= a2
    out += 1.0 / 120.0
    out *= a2
    out -= 1.0 / 6.0
    out *= a2
    out += 1.0
    return out


def _hankel2_0(z):
    """H_0^(2)(z) = J_0(z) - j Y_0(z) for real z > 0 (SciPy/Cephes Bessel functions)."""
    out = np.empty(z.shape, dtype=complex)
    out.real = scipy.special.j0(z)
    out.imag = scipy.special.y0(z)
    out.imag *= -1.0
    return out


def _segment_integral(xm, ym, xn, yn, half_dx, slope, k=K0):
    """int over the straight pulse segment n of H_0^(2)(k |rho_m - rho'|) dC' (8-point Gauss-Legendre).

    The segment spans x in [xn - half_dx, xn + half_dx] with height yn + slope (x - xn);
    dC' = sqrt(1 + slope^2) dx.  Used for near neighbours, where the midpoint rule
    misses the logarithmic variation of Y_0.
    """
    t = half_dx[..., None] * _GL_X
    xs = xn[..., None] + t
    ys = yn[..., None] + slope[..., None] * t
    r = np.hypot(xm[..., None] - xs, ym[..., None] - ys)
    jac = half_dx * np.sqrt(1.0 + slope**2)
    return (_hankel2_0(k * r) @ _GL_W) * jac


def _self_term(seg_len, k=K0):
    """Eq. 20 self term: int over the pulse's own segment of H_0^(2)(k|t|) dt, t in [-D/2, D/2].

    The singular part comes from the small-argument expansion
    H_0^(2)(z) ~ 1 - j (2/pi) ln(gamma z / 2), gamma = e^{Euler} = 1.781...,
    integrated analytically (Peterson, Ray & Mittra, Ref. 40):
    D [1 - j (2/pi) ln(gamma k D / (4 e))].  The smooth remainder
    H_0^(2)(z) - [1 - j(2/pi) ln(gamma z/2)] = O(z^2 ln z) is added by Gauss-Legendre
    quadrature (it is ~1% of the term at 10 points per wavelength).
    """
    analytic = seg_len * (1.0 - 2j / math.pi * np.log(EULER_GAMMA_EXP * k * seg_len / (4.0 * math.e)))
    half = seg_len / 2.0
    t = half[:, None] * (_GL_X + 1.0) / 2.0  # nodes on (0, D/2)
    z = k * t
    remainder = _hankel2_0(z) - (1.0 - 2j / math.pi * np.log(EULER_GAMMA_EXP * z / 2.0))
    return analytic + 2.0 * (remainder @ _GL_W) * (half / 2.0)


def moment_matrix(x, y, dfdx, dx, k=K0, near=4, block=256):
    """The EFIE moment matrix of Eq. 20 with Z0 factored out: A_mn = (k/4) int_{C_n} H_0^(2)(k|rho_m - rho'|) dC'.

    Pulse basis on straight segments of x-width ``dx`` centred on (x_n, y_n) with
    slope ``dfdx[n]`` (arc length D_n = dx sqrt(1 + f'^2)); delta testing at the
    segment centres.  Far entries use the midpoint rule with the segment's phase
    variation, D_n H_0^(2)(k R_mn) sinc(k D_n cos(psi_mn) / 2) (psi: angle between
    the segment and the line to the match point; the bare midpoint rule would make
    a flat plate's current 1 % too large at 10 points per wavelength); entries
    with |m - n| <= ``near`` use 8-point Gauss-Legendre over the source segment;
    the diagonal is :func:`_self_term`.  ``k/4 = pi/(2 lambda)`` is
    Eq. 18's prefactor over Z0.

    Parameters
    ----------
    x, y, dfdx : ndarray [N], wavelengths.  dx : float, sample spacing.

    Returns
    -------
    ndarray [N, N] complex128, so that A @ (Z0 J) = E_i at the match points.
    """
    n = x.size
    seg_len = dx * np.sqrt(1.0 + dfdx**2)
    A = np.empty((n, n), dtype=complex)
    # H_0^(2)(k R) is symmetric: fill the upper triangle by row blocks and mirror it
    for r0 in range(0, n, block):
        r1 = min(n, r0 + block)
        ddx = x[r0:r1, None] - x[None, r0:]
        ddy = y[r0:r1, None] - y[None, r0:]
        kr = ddx * ddx
        kr += ddy * ddy
        np.sqrt(kr, out=kr)
        kr *= k
        # guard: the diagonal (R = 0) is replaced by the self term below; avoid Y_0(0) = -inf
        diag = (np.arange(r1 - r0), np.arange(r0, r1) - r0)
        kr[diag] = 1.0
        h = _hankel2_0(kr)
        # midpoint rule with the segment's phase variation: int e^{-j k R(t)} dt over a segment
        # of length D seen under angle psi ~ D sinc(k D cos(psi) / 2)  (the bare midpoint rule
        # is off by (k D)^2 / 24, 1.6 % at 10 points per wavelength)
        # source n (upper block): k D_n cos(psi) / 2 = k dx (ddx + ddy f'_n) / (2 R), kr = k R
        c_up = (ddx + ddy * dfdx[None, r0:]) * (k * k * dx / 2.0)
        c_up /= kr
        c_lo = (ddx + ddy * dfdx[r0:r1, None]) * (k * k * dx / 2.0)
        c_lo /= kr
        up = h * _sinc(c_up)
        up *= seg_len[None, r0:]
        lo = h * _sinc(c_lo)
        lo *= seg_len[r0:r1, None]
        A[r0:r1, r0:] = up
        A[r0:, r0:r1] = lo.T
    # near neighbours: accurate segment integrals
    for d in range(1, near + 1):
        m = np.arange(n - d)
        half = np.full(n - d, dx / 2.0)
        A[m, m + d] = _segment_integral(x[m], y[m], x[m + d], y[m + d], half, dfdx[m + d], k)
        A[m + d, m] = _segment_integral(x[m + d], y[m + d], x[m], y[m], half, dfdx[m], k)
    A[np.arange(n), np.arange(n)] = _self_term(seg_len, k)
    A *= k / 4.0
    return A


def incident_field(x, y, theta_i, k=K0):
    """Right-hand side of Eqs. 18/20: E_i = exp(-j k (x sin ti - y cos ti)) at the match points.

    theta_i : ndarray [n_ti] radians.  Returns [N, n_ti] complex.
    """
    ti = np.atleast_1d(theta_i)
    return np.exp(-1j * k * (x[:, None] * np.sin(ti)[None, :] - y[:, None] * np.cos(ti)[None, :]))


def taper(x, x_center, w):
    """Eq. 22: Gaussian taper W(x) = exp(-((x - x_m)/w)^2) applied to the current."""
    return np.exp(-(((x - x_center) / w) ** 2))


def incident_flux(x, dfdx, dx, window, theta_i):
    """Incident power through the windowed surface, in units of |E_i|^2/(2 Z0): sum_n W_n^2 (cos ti + f'_n sin ti) dx.

    The plane wave's flux through the surface element (-f', 1) dx is
    (cos ti + f' sin ti) dx; weighted by the taper squared it is the power the
    windowed current must send back (a PEC absorbs nothing).  For a flat
    partition it is w sqrt(pi/2) cos ti, Eq. 23's normaliser; on a rough one it
    differs by the partition's random tilt sin(ti) sum W^2 f' dx, which is
    zero on average but does not average away quickly near grazing.
    Returns [n_ti].
    """
    ti = np.atleast_1d(theta_i)
    w2 = window * window * dx
    return np.cos(ti) * w2.sum() + np.sin(ti) * (w2 @ dfdx)


def far_field(x, y, dfdx, dx, current, theta_r, k=K0):
    """Eq. 21's far-field sum F(tr) = sum_n I_n int_{C_n} exp(j k (x' sin tr + y' cos tr)) dC'.

    The integral over each straight pulse segment is exact:
    dx sqrt(1+f'^2) * exp(j k (x_n u + y_n c)) * sinc(k dx (u + f'_n c) / 2) with
    u = sin tr, c = cos tr (the sinc follows the staircase current the pulses
    represent).  ``current`` [N, n_ti] is the (tapered) Z0 J; returns [n_ti, n_tr].
    """
    uc = np.stack([np.sin(theta_r), np.cos(theta_r)], axis=1)  # [n_tr, 2]
    phase = uc @ (k * np.stack([x, y]))  # k (x_n u + y_n c), [n_tr, N]
    kern = np.exp(1j * phase)
    kern *= _sinc(uc @ ((k * dx / 2.0) * np.stack([np.ones_like(dfdx), dfdx])))
    weights = current * (dx * np.sqrt(1.0 + dfdx**2))[:, None]
    return (kern @ weights).T


def power_grid(w, k=K0):
    """Observation grid over [-pi/2, pi/2] (radians) on which the power balance is integrated.

    The tapered current's far-field power |F(u)|^2, u = sin(theta), is the Fourier
    transform of the current's autocorrelation, which spans |x| < ~4 w; so the
    trapezoid rule in theta integrates it to round-off once the step is below
    ~2 pi / (k 4 w) in u, and the coherent spike (standard deviation 1/(k w) in u)
    to 1e-8 with a step of 1/(k w).  We take min(0.25 deg, 1/(k w)).
    """
    h = min(math.radians(0.25), 1.0 / (k * w))
    n = int(math.ceil(math.pi / h)) + 1
    return np.linspace(-math.pi / 2.0, math.pi / 2.0, n)


# ---------------------------------------------------------------------------
# Failure checks
# ---------------------------------------------------------------------------

def check_sampling(pts_per_wl, corr_length_wl=None, rough=True):
    """Warn (MoMAccuracyWarning) or raise when the pulse sampling cannot resolve field or surface."""
    if not (math.isfinite(pts_per_wl) and pts_per_wl >= 2.0):
        raise ValueError(f"pts_per_wl must be >= 2 (the pulses cannot represent a wave below that), got {pts_per_wl}")
    reasons = []
    if pts_per_wl < 5.0:
        reasons.append(f"pts_per_wl={pts_per_wl:g} is below ~5 points per wavelength: the pulse-basis current "
                       "does not resolve the field; expect errors of a few percent or more")
    if rough and corr_length_wl is not None and corr_length_wl * pts_per_wl < 5.0:
        reasons.append(f"only {corr_length_wl * pts_per_wl:.1f} samples per correlation length: the surface "
                       "curvature is not resolved")
    for r in reasons:
        warnings.warn("MoM failure risk: " + r, MoMAccuracyWarning, stacklevel=3)
    return reasons


def check_taper(theta_i, w, partition_length):
    """Warn when the Gaussian taper (Eq. 22) is too narrow for theta_i or too wide for the partition.

    Thorsos (JASA 83, 78 (1988)) shows that a Gaussian-windowed plane wave of
    width w stands for a plane wave only while (1 + 2 tan^2 ti)/(k w cos ti)^2 << 1;
    and the window's angular spectrum, of standard deviation 1/(k w) in sin(theta),
    must stay inside the visible range: sin ti + 3/(k w) < 1.  The first is
    also the size of the power error it causes: integrating the windowed
    specular spike over theta_r picks up 1/cos(theta_r), whose average over the
    spike (std 1/(k w cos ti) in theta) exceeds 1/cos(ti) by about half of
    Thorsos' parameter; the limit 0.02 thus flags power errors above ~1 %.
    """
    reasons = []
    for ti in np.atleast_1d(theta_i):
        thorsos = (1.0 + 2.0 * math.tan(ti) ** 2) / (K0 * w * math.cos(ti)) ** 2
        if thorsos > THORSOS_LIMIT or math.sin(ti) + 3.0 / (K0 * w) >= 1.0:
            reasons.append(f"taper too narrow for theta_i={math.degrees(ti):.1f} deg (grazing): "
                           f"w={w:.3g} wavelengths gives Thorsos' (1+2tan^2 ti)/(k w cos ti)^2={thorsos:.3g} "
                           f"> {THORSOS_LIMIT} or spectrum beyond grazing; lengthen the partitions")
    if w > partition_length / 3.0:
        reasons.append(f"taper width w={w:.3g} exceeds a third of the partition length {partition_length:.3g}: "
                       "the partition ends are not windowed away (edge diffraction)")
    for r in reasons:
        warnings.warn("MoM failure risk: " + r, MoMAccuracyWarning, stacklevel=3)
    return reasons


def check_partition(partition_length, corr_length_wl, rough=True):
    """Warn when partitions are too short for the correlation length (fewer than 10 ell)."""
    reasons = []
    if rough and partition_length < 10.0 * corr_length_wl:
        reasons.append(f"partitions of {partition_length:.3g} wavelengths are shorter than 10 correlation "
                       f"lengths ({10 * corr_length_wl:.3g}): too few independent facets per partition")
    for r in reasons:
        warnings.warn("MoM failure risk: " + r, MoMAccuracyWarning, stacklevel=3)
    return reasons


# ---------------------------------------------------------------------------
# One partition (the unit of parallel work)
# ---------------------------------------------------------------------------

def _openblas_libs():
    """(set_num_threads, get_num_threads) ctypes functions of every OpenBLAS loaded in this process.

    NumPy's and SciPy's wheels each bundle OpenBLAS; we reach their thread
    controls through ctypes (what threadpoolctl does) and skip any we cannot find.
    """
    try:
        maps = open("/proc/self/maps").read().split("\n")
    except OSError:  # not Linux: leave the BLAS alone
        return []
    paths = {line.split()[-1] for line in maps if "openblas" in line.lower() and line.split()[-1].startswith("/")}
    found = []
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for suffix in ("64_", "", "_64_"):
            set_fn = getattr(lib, "scipy_openblas_set_num_threads" + suffix, None)
            get_fn = getattr(lib, "scipy_openblas_get_num_threads" + suffix, None)
            if set_fn is not None and get_fn is not None:
                found.append((set_fn, get_fn))
                break
        else:
            set_fn = getattr(lib, "openblas_set_num_threads", None)
            get_fn = getattr(lib, "openblas_get_num_threads", None)
            if set_fn is not None and get_fn is not None:
                found.append((set_fn, get_fn))
    return found


def _limit_blas_threads(n=1):
    """Limit OpenBLAS to n threads in this process; returns the previous counts (for restoring)."""
    previous = []
    for set_fn, get_fn in _openblas_libs():
        previous.append((set_fn, int(get_fn())))
        set_fn(int(n))
    return previous


def _restore_blas_threads(previous):
    for set_fn, count in previous:
        set_fn(count)


def _worker_init():
    _limit_blas_threads(1)


def solve_partition(task):
    """Solve one partition: fill, LU-factor once, solve every theta_i, taper, radiate.

    ``task`` is a dict with x, y, dfdx (local coordinates, centred on the
    partition), dx, theta_i [rad], theta_r [rad], theta_fine [rad] (the power
    grid), w.  Returns a dict with the
    far fields ``F`` [n_ti, n_tr] and ``F_fine`` [n_ti, len(theta_fine)],
    and the CPU seconds (process time) of each stage.
    """
    clock = time.process_time  # CPU seconds of this process (its BLAS is single-threaded in the pool)
    t0 = clock()
    x, y, dfdx, dx = task["x"], task["y"], task["dfdx"], task["dx"]
    A = moment_matrix(x, y, dfdx, dx)
    t1 = clock()
    # factor A^T: its transpose view is Fortran-ordered, so LAPACK works in place (no copy)
    # and lu_solve(..., trans=1) solves (A^T)^T J = A J = E_i
    lu = scipy.linalg.lu_factor(A.T, overwrite_a=True, check_finite=False)
    del A
    t2 = clock()
    current = scipy.linalg.lu_solve(lu, incident_field(x, y, task["theta_i"]), trans=1, check_finite=False)
    del lu
    win = taper(x, 0.0, task["w"])
    current *= win[:, None]
    t3 = clock()
    F = far_field(x, y, dfdx, dx, current, task["theta_r"])
    F_fine = far_field(x, y, dfdx, dx, current, task["theta_fine"])
    t4 = clock()
    return {"F": F, "F_fine": F_fine, "flux": incident_flux(x, dfdx, dx, win, task["theta_i"]),
            "times": np.array([t1 - t0, t2 - t1, t3 - t2, t4 - t3])}


class SerialExecutor(cf.Executor):
    """A concurrent.futures.Executor that runs each task at once in the calling process.

    For small problems (tests), where starting a process pool costs more than the work.
    """

    def submit(self, fn, /, *args, **kwargs):
        fut = cf.Future()
        # one BLAS thread while the task runs: threaded BLAS only slows down these matrix sizes
        # (the 2-thread LU of a 500-unknown partition is 10x slower here) -- restored afterwards
        previous = _limit_blas_threads(1)
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # hand the error to the caller through the future
            fut.set_exception(exc)
        finally:
            _restore_blas_threads(previous)
        return fut


# ---------------------------------------------------------------------------
# Public entry point
# ---------------------------------------------------------------------------

@dataclass
class MoMResult:
    """Result of :func:`scatter` (angles in radians; ``*_deg`` copies in degrees).

    Attributes
    ----------
    theta_i, theta_r : ndarray [n_ti], [n_tr], radians (signed theta_r, + = forward/specular side).
    sigma : ndarray [n_ti, n_tr], Eq. 23 (dimensionless: 2-D RCS per effective
        illuminated length), coherent plus incoherent.
    sigma_coherent, sigma_incoherent : same shape, the split |<F>|^2 / rest.
    power_balance : ndarray [n_ti], reflected / incident power (1 for a PEC): the
        far-field power of the windowed currents over the incident power through
        the windowed surfaces (:func:`incident_flux`, the partitions' tilt included).
    power_balance_nominal : ndarray [n_ti], the same over the nominal incident
        power of Eq. 23, (1/(2 pi cos ti)) int sigma d tr; it carries the sample's
        tilt noise, ~ tan(ti) sqrt(2) sigma_h / (w sqrt(pi/2) sqrt(M)).
    power_coherent : ndarray [n_ti], the coherent (specular) share of the nominal power.
    fine_theta_r, fine_sigma : the internal power grid (:func:`power_grid`) and sigma on it.
    sigma_std_error : ndarray [n_ti, n_tr], standard error of sigma from the
        spread between partitions (the speckle left by a finite M).
    times : dict of summed worker CPU seconds (process time) per stage ("fill",
        "factor", "solve", "far_field") and the wall time of the call ("wall").
    params : dict of the run's parameters (taper width w, dx, N per partition, ...).
    warnings : list of str, the MoM failure reasons found for this run.
    """

    theta_i: np.ndarray
    theta_r: np.ndarray
    sigma: np.ndarray
    sigma_coherent: np.ndarray
    sigma_incoherent: np.ndarray
    power_balance: np.ndarray
    power_balance_nominal: np.ndarray
    power_coherent: np.ndarray
    fine_theta_r: np.ndarray
    fine_sigma: np.ndarray
    sigma_std_error: np.ndarray
    times: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)

    @property
    def theta_i_deg(self):
        return np.degrees(self.theta_i)

    @property
    def theta_r_deg(self):
        return np.degrees(self.theta_r)


def _check_positive(name, value, allow_zero=False):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    ok = math.isfinite(v) and (v >= 0.0 if allow_zero else v > 0.0)
    if not ok:
        raise ValueError(f"{name} must be finite and {'>= 0' if allow_zero else '> 0'}, got {value!r}")
    return v


def process_pool(max_workers=None):
    """The default executor: a process pool whose workers each run single-threaded BLAS.

    One worker per core (``os.cpu_count()``) unless ``max_workers`` says otherwise;
    one BLAS thread per worker, since the partitions already keep every core busy.
    """
    workers = max(1, int(max_workers or os.cpu_count() or 1))
    ctx = multiprocessing.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init)


class _Progress:
    """A stderr progress report: a rewritten line on a terminal, a line every 10 s otherwise."""

    def __init__(self, total, enabled):
        self.total, self.enabled = total, enabled
        self.t0 = time.perf_counter()
        self.last = 0.0
        self.tty = hasattr(sys.stderr, "isatty") and sys.stderr.isatty()

    def update(self, done):
        if not self.enabled:
            return
        now = time.perf_counter() - self.t0
        step = 0.5 if self.tty else 10.0
        if done < self.total and now - self.last < step:
            return
        if done == self.total and now < 1.0:
            return  # a short run needs no report
        self.last = now
        eta = now / done * (self.total - done)
        start = "\r" if self.tty else ""
        end = "" if (self.tty and done < self.total) else "\n"
        sys.stderr.write(start + f"mom: partition {done}/{self.total}, {now:.1f} s elapsed, ~{eta:.0f} s left " + end)
        sys.stderr.flush()


def scatter(length_wl, partitions, rms_height_wl, corr_length_wl, theta_i_deg, theta_r_deg,
            pts_per_wl=10, seed=0, executor=None, *, taper_width_wl=None, progress=None):
    """Incoherent far-field scattering of a 1-D Gaussian rough PEC surface, TM (s-pol) -- paper Eqs. 18-23.

    Parameters
    ----------
    length_wl : float, total surface length (wavelengths), cut into ``partitions``
        equal, consecutive partitions of length L_p = length_wl / partitions.
    partitions : int >= 1, M of Eq. 23.
    rms_height_wl, corr_length_wl : float, sigma_h (>= 0; 0 = flat plate) and ell (> 0)
        in wavelengths, Gaussian height statistics with correlation
        sigma_h^2 exp(-x^2/ell^2); the paper's rms slope is sqrt(2) sigma_h / ell.
    theta_i_deg : float or sequence, incidence angles in [0, 90) degrees.
    theta_r_deg : float or sequence, signed observation angles in [-90, 90]
        degrees (+ = specular side).
    pts_per_wl : float, pulses per wavelength along x (default 10).
    seed : int, surface realisation (same seed, same surface at any pts_per_wl).
    executor : concurrent.futures.Executor or None.  None: a process pool with
        one worker per core (each worker single-threaded BLAS); pass
        :class:`SerialExecutor` for in-process runs or a dask executor to spread
        partitions across machines.  A caller's executor is not shut down.
    taper_width_wl : float, keyword-only, Eq. 22's w (default L_p / 4).
    progress : bool or None, keyword-only; None shows a stderr line for runs of
        10 or more partitions.

    Returns
    -------
    MoMResult with ``theta_r`` [rad], ``sigma`` [n_theta_i, n_theta_r] (Eq. 23),
    ``power_balance`` [n_theta_i] and more (see :class:`MoMResult`).

    Warns
    -----
    MoMAccuracyWarning where the MoM answer cannot be trusted (see module docstring).
    """
    t_wall = time.perf_counter()
    length_wl = _check_positive("length_wl", length_wl)
    if int(partitions) != partitions or partitions < 1:
        raise ValueError(f"partitions must be an integer >= 1, got {partitions!r}")
    partitions = int(partitions)
    rms_height_wl = _check_positive("rms_height_wl", rms_height_wl, allow_zero=True)
    corr_length_wl = _check_positive("corr_length_wl", corr_length_wl)
    pts_per_wl = _check_positive("pts_per_wl", pts_per_wl)
    ti_deg = np.atleast_1d(np.asarray(theta_i_deg, dtype=float))
    tr_deg = np.atleast_1d(np.asarray(theta_r_deg, dtype=float))
    if ti_deg.ndim != 1 or not np.all(np.isfinite(ti_deg)) or np.any(ti_deg < 0) or np.any(ti_deg >= 90):
        raise ValueError(f"theta_i_deg must be finite angles in [0, 90) degrees, got {theta_i_deg!r}")
    if tr_deg.ndim != 1 or not np.all(np.isfinite(tr_deg)) or np.any(np.abs(tr_deg) > 90):
        raise ValueError(f"theta_r_deg must be finite signed angles in [-90, 90] degrees, got {theta_r_deg!r}")
    theta_i = np.radians(ti_deg)
    theta_r = np.radians(tr_deg)
    rough = rms_height_wl > 0.0

    part_len = length_wl / partitions
    n_part = int(round(part_len * pts_per_wl))
    if n_part < 4:
        raise ValueError(f"partitions of {part_len:g} wavelengths at pts_per_wl={pts_per_wl:g} hold fewer than 4 pulses")
    dx = part_len / n_part
    w = part_len / 4.0 if taper_width_wl is None else _check_positive("taper_width_wl", taper_width_wl)

    reasons = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MoMAccuracyWarning)  # re-issued below from this frame
        reasons += check_sampling(1.0 / dx, corr_length_wl, rough)
        reasons += check_taper(theta_i, w, part_len)
        reasons += check_partition(part_len, corr_length_wl, rough)
    for r in reasons:
        warnings.warn("MoM failure risk: " + r, MoMAccuracyWarning, stacklevel=2)

    fine = power_grid(w)
    try:
        x_all, f_all, s_all = gaussian_surface(length_wl, n_part * partitions, rms_height_wl, corr_length_wl, seed)
    except ValueError as exc:
        raise ValueError(f"pts_per_wl={pts_per_wl:g} is too coarse for corr_length_wl={corr_length_wl:g} "
                         f"(the surface spectrum needs > {3.9 / corr_length_wl:.3g} points per wavelength): {exc}") from None
    tasks = []
    for m in range(partitions):
        sl = slice(m * n_part, (m + 1) * n_part)
        xc = (m + 0.5) * part_len
        # local coordinates centred on the partition: the incident phase is referred to x_m,
        # so the partition average of F is the coherent field
        tasks.append({"x": x_all[sl] - xc, "y": f_all[sl].copy(), "dfdx": s_all[sl].copy(), "dx": dx,
                      "theta_i": theta_i, "theta_r": theta_r, "theta_fine": fine, "w": w})
    del x_all, f_all, s_all

    own = executor is None
    ex = process_pool(min(os.cpu_count() or 1, partitions)) if own else executor
    show = (partitions >= 10) if progress is None else bool(progress)
    bar = _Progress(partitions, show)
    n_ti, n_tr, n_f = theta_i.size, theta_r.size, fine.size
    sum_F = np.zeros((n_ti, n_tr), complex)
    sum_P = np.zeros((n_ti, n_tr))
    sum_P2 = np.zeros((n_ti, n_tr))
    sum_Ff = np.zeros((n_ti, n_f), complex)
    sum_Pf = np.zeros((n_ti, n_f))
    times = np.zeros(4)
    sum_flux = np.zeros(n_ti)
    try:
        futures = [ex.submit(solve_partition, t) for t in tasks]
        del tasks
        for done, fut in enumerate(cf.as_completed(futures), start=1):
            out = fut.result()
            P = np.abs(out["F"]) ** 2
            sum_F += out["F"]
            sum_P += P
            sum_P2 += P * P
            sum_Ff += out["F_fine"]
            sum_Pf += np.abs(out["F_fine"]) ** 2
            times += out["times"]
            sum_flux += out["flux"]
            bar.update(done)
    finally:
        if own:
            ex.shutdown(wait=True, cancel_futures=True)

    M = partitions
    # Eq. 23: sigma = 1/(w sqrt(pi/2)) * (1/M) sum_m (pi/2) |Z0 F_m|^2   (lambda = 1)
    norm = (math.pi / 2.0) / (w * math.sqrt(math.pi / 2.0))
    sigma = norm * sum_P / M
    # |<F>|^2 without the 1/M bias of |mean F|^2:  (M |mean F|^2 - mean |F|^2) / (M - 1)
    # (an estimate: it can come out slightly negative where the coherent part is ~0)
    def coherent(sF, sP):
        if M == 1:
            return norm * np.abs(sF) ** 2
        return norm * (np.abs(sF / M) ** 2 * M - sP / M) / (M - 1)

    sigma_coh = coherent(sum_F, sum_P)
    var = np.maximum(sum_P2 / M - (sum_P / M) ** 2, 0.0)  # guard: round-off can make it slightly negative
    std_err = norm * np.sqrt(var / max(M - 1, 1))
    fine_sigma = norm * sum_Pf / M
    fine_coh = coherent(sum_Ff, sum_Pf)
    cos_i = np.cos(theta_i)
    # reflected power per unit incident power on the nominal (flat, Eq. 23) illuminated length
    power_nominal = np.trapezoid(fine_sigma, fine, axis=1) / (2.0 * math.pi * cos_i)
    power_coh = np.trapezoid(fine_coh, fine, axis=1) / (2.0 * math.pi * cos_i)
    # ... and per unit incident power actually falling on the windowed partitions (tilt included)
    nominal_flux = M * w * math.sqrt(math.pi / 2.0) * cos_i
    power = power_nominal * nominal_flux / sum_flux
    if not (np.all(np.isfinite(sigma)) and np.all(np.isfinite(power))):
        raise FloatingPointError("MoM produced non-finite values (singular moment matrix?)")
    wall = time.perf_counter() - t_wall
    return MoMResult(
        theta_i=theta_i, theta_r=theta_r, sigma=sigma, sigma_coherent=sigma_coh,
        sigma_incoherent=sigma - sigma_coh, power_balance=power, power_balance_nominal=power_nominal,
        power_coherent=power_coh,
        fine_theta_r=fine, fine_sigma=fine_sigma, sigma_std_error=std_err,
        times={"fill": times[0], "factor": times[1], "solve": times[2], "far_field": times[3], "wall": wall},
        params={"length_wl": length_wl, "partitions": M, "partition_length_wl": part_len,
                "unknowns_per_partition": n_part, "dx_wl": dx, "pts_per_wl": 1.0 / dx,
                "taper_width_wl": w, "rms_height_wl": rms_height_wl, "corr_length_wl": corr_length_wl,
                "rms_slope": math.sqrt(2.0) * rms_height_wl / corr_length_wl, "seed": seed},
        warnings=reasons,
    )
