"""Method-of-moments (MoM) reference solver for a random rough surface (paper Section 3), both polarisations.

What it computes
----------------
The paper's Fig. 6 reference and its extension to polarisation: a 1-D random
rough surface ``y = f(x)`` (invariant along z), perfectly conducting or of a
finite complex index eta = n - j kappa (the paper's sign, e^{+j w t}), lit by an
s-polarised (TM_z, E along z) and/or p-polarised (TE_z, H along z) plane wave on
the *same* surface realisation.  The long surface is cut into ``M``
partitions; each partition's surface fields are windowed by the Gaussian
taper of Eq. 22, radiated to the far field (Eq. 21), and the partitions'
far-field powers (and the s-p cross products) are averaged incoherently and
normalised by the taper's effective length (Eq. 23).

Formulation (exact to discretisation; :mod:`hyde_bsdf.mom.kernels` has the details)
-----------------------------------------------------------------------------------
With psi = E_z (s) or H_z (p), u = psi and v = sqrt(1 + f'^2) d psi/dn on the
surface, g_i = -(j/4) H_0^(2)(k_i R), k_1 = k0 eta, Green's theorem above and
below the surface gives the two-region equations (Tsang, Kong, Ding & Ao,
*Scattering of Electromagnetic Waves: Numerical Simulations*, Wiley 2001, the
chapter on 1-D rough surfaces; Sanchez-Gil & Nieto-Vesperinas, JOSA A 8, 1270 (1991))

    (1/2) u - D_0 u + S_0 v = psi_inc,        (1/2) u + D_1 u - rho S_1 v = 0,

rho = 1 (s) or eta^2 (p).  PEC: u = 0 (s: the EFIE S_0 v = psi_inc, the
paper's Eq. 18) or v = 0 (p: the MFIE (1/2 - D_0) u = psi_inc).  The interior
equation is solved first, u = rho Z v with Z = (1/2 + D_1)^-1 S_1 (banded in a
metal, whose Green's function dies within a few skin depths), leaving one N x N
system (rho (1/2 - D_0) Z + S_0) v = psi_inc per polarisation.  Discretisation:
Nystrom samples at the cell centres; near cells (|m - n| <= 4) integrated by
Gauss-Legendre over the osculating parabola with a quadratic interpolant of the
samples and panels no longer than one decay length 1/|Im k_1|; far cells with
the kernel's phase (and Hankel amplitude slope) integrated exactly against the
same interpolant; the log singularity of the self cell analytically.  (Pulse
bases with point matching are 1-2 % off at 10 points per wavelength for p and
for metals: the interior kernel, much narrower than a cell, sees the pulses'
steps.)  Far field F(theta) = int [j k0 (-f' sin theta + cos theta) u - v]
e^{j k0 (x sin theta + y cos theta)} dx, sigma = |F|^2 / (8 pi w sqrt(pi/2)).
E_p is taken in the right-handed (s, p, k) basis of :mod:`hyde_bsdf.model.fresnel`
for incident and scattered wave (E_p = -Z0 H_z), so a flat PEC gives r_s = -1,
r_p = +1 and the Mueller matrix diag(1, 1, -1, -1); M00 = (sigma_s + sigma_p)/2,
M01 = (sigma_s - sigma_p)/2, M22 + j M23 = <F_s F_p*> normalised like sigma.
Absorbed power (Poynting on the vacuum side): P_abs = -(1/k0) int W^2 Im(u v*) dx
over the incident flux through the windowed surface; energy = reflected + absorbed.

Measured (hyde_bsdf/validation/mom_polarization.py): a flat plate of Infragold, flame-sprayed
Al or glass reproduces Fresnel |r_s|^2, |r_p|^2 within 0.006 and arg(r_p/r_s)
within 0.35 deg for theta_i = 0-80 deg at the default 10 points per wavelength.

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
* a windowed current (``incidence="window"``, the paper's Eq. 22) whose estimated power error
  exceeds ``TAPER_TOLERANCE`` = 1 % in either polarisation, or whose taper's angular spectrum
  (3 standard deviations, ``3/(k w)`` in sin(theta)) crosses grazing: the estimate is the exact
  flat-PEC law :func:`hyde_bsdf.mom.beam.window_bias` (measured: s 1 + 0.82 tau, p 1 - 0.26 tau at
  Thorsos' tau = (1 + 2 tan^2 ti)/(k w cos ti)^2 = 0.02), given in the message;
* partitions are too short for the correlation length (partition shorter than
  10 correlation lengths): a partition then holds too few independent facets
  and the surface is no longer a stationary random sample at the partition
  scale;
* the taper is too wide for the partition (w > L_p/3): the truncated ends of
  the partition are not windowed away and edge diffraction leaks in;
* fewer than 5 points per interior wavelength lambda / max(1, n) (below 2 a
  ValueError naming pts_per_wl);
* after the solve, reflected + absorbed power off 1 by more than
  ``ENERGY_TOLERANCE`` = 0.01 in either polarisation at any theta_i (the value
  is in the message): a result that fails the energy check never comes back
  unwarned.

Incidence near grazing
----------------------
``incidence="auto"`` (default) lights theta_i >= ``BEAM_FROM_DEG`` = 80 deg with an exact Gaussian
beam of footprint w (:mod:`hyde_bsdf.mom.beam`: unwindowed currents, sigma normalised by the beam's
power, the power balance by its flux through the surface) and the windowed plane-wave current of
Eq. 22 below (the paper's Fig. 6 is unchanged).  The windowed current's power is biased (above) and,
in s, its forward-grazing sigma has an artificial floor (-44.5 dB below the specular peak of an 80-deg
flat plate at L = 4 w: the lit partition ends launch surface waves that reach the window); the beam
reflects 1.0000 (p) and 1.0026 (s, the sampling) off a flat PEC at any tau and follows the analytic
reflected beam to -98 dB (hyde_bsdf/validation/mom_forward_grazing.py).

and it refuses (ValueError naming the parameter) before allocating when
* the realised surface is so steep that ``pts_per_wl`` along x gives fewer than
  ``ARC_PTS_MIN`` = 5 points per wavelength of *arc length* at its steepest point,
  or a turn of more than ``TURN_MAX`` = 0.3 rad per cell: the surface is then
  resampled finer (``params["pts_per_wl"]``), and refused if that needs more than
  ``MAX_UNKNOWNS`` = 10000 unknowns per partition for the dense solver (``MAX_FAST_UNKNOWNS``
  = 200000 for the fast one, which also needs the surface's height range to fit its
  blocks) or more memory than is available (:func:`hyde_bsdf.resources.available_memory`);
* the fast solver misses its tolerance (after GMRES) and the dense fallback would not fit in
  memory or would cost more than ``DENSE_FALLBACK_RATIO`` = 10 x the fast solve: the result keeps
  the residual reached, with a warning naming ``tol`` (or, where the fast solver cannot take the
  surface at all, a UsageError naming ``partitions``);
* the skin depth would need more than ``MAX_PANELS`` = 64 quadrature panels per cell;
* ``taper_width_wl`` exceeds the partition length, ``seed`` is not an integer
  >= 0, ``polarization`` is not "s"/"p"/both, or n, k are out of range.

Known limitation: at grazing incidence (75 deg on the Figs. 8-9 surfaces, 80 deg on a
flat plate) the truncated partition ends launch p-polarised waves along a metal whose
absorption under the window is counted; with the default w = L_p / 4 reflected + absorbed
then comes out a few percent high (the reflected power itself is unaffected).  The
absorption decays with the ends' distance from the window: Infragold at 80 deg, +1.3 %
of the incident power at L_p = 4 w, +0.34 % at 8 w, +0.19 % at 12 w (pass a
``taper_width_wl`` below L_p / 4; the fast solver makes such partitions affordable).

Stages and solvers
------------------
:func:`scatter` runs in stages: ``_check_inputs`` (every argument), ``_realise_surface``
(the realisation, its resampling, the method and the set-up's failure reasons),
``_partition_tasks``, ``_solve_partitions`` (each partition by :func:`solve_partition`:
surface fields by the chosen method, then taper, absorbed power and far field),
``_statistics`` (Eq. 23, standard errors, Mueller elements) and ``_energy_check``.  One
module per solution method: :mod:`hyde_bsdf.mom.dense` (LU of the full matrix) and
:mod:`hyde_bsdf.mom.fast` (forward-backward sweeps with spectral acceleration, a GMRES fallback on the
fast operator, the dense LU only where affordable); :mod:`hyde_bsdf.mom.beam` the grazing beam;
:mod:`hyde_bsdf.mom.runtime` the workers' BLAS and heap tuning.

Parallelism
-----------
Partitions are independent tasks submitted to a :class:`concurrent.futures.Executor`
(a process pool by default; ``client.get_executor()`` of a dask.distributed
client works the same way).  With the dense method each worker fills its matrix,
factors it once with :func:`scipy.linalg.lu_factor` and solves all incidence angles
as right-hand sides; no worker holds more than one partition's matrix.  The fast
method holds O(N) numbers per partition (Q plane-wave factors per sample) and sweeps
all incidence angles at once.
"""
from __future__ import annotations

import concurrent.futures as cf
import functools
import math
import multiprocessing
import os
import sys
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from hyde_bsdf import resources
from hyde_bsdf.errors import UsageError
from hyde_bsdf.options import Options
from hyde_bsdf.model.index import Index
from hyde_bsdf.model.parameters import NATURAL_INDEX
from hyde_bsdf.progress import Throttle, as_callback
from hyde_bsdf.mom import cost as _cost
from hyde_bsdf.mom.beam import gaussian_beam, window_bias
from hyde_bsdf.mom.dense import check_finite_surface, solve_dense
from hyde_bsdf.mom.fast import FAST_TOL, NEAR_WL, FastSolverUnsuitable, block_length_wl, plan_blocks, solve_fast
from hyde_bsdf.mom.floor import FLOOR_MARGIN, floor_reason, partition_floor
from hyde_bsdf.mom.gather import ExecutorError, check_executor, end_pool, gather
from hyde_bsdf.mom.kernels import absorbed_flux, far_field_uv
from hyde_bsdf.mom.runtime import limit_blas_threads, restore_blas_threads, worker_init

__all__ = [
    "scatter",
    "MoMOptions",
    "estimate",
    "MoMResult",
    "MoMAccuracyWarning",
    "SerialExecutor",
    "ExecutorError",
    "process_pool",
    "gaussian_surface",
    "incident_field",
    "incident_flux",
    "taper",
    "check_sampling",
    "check_taper",
    "check_partition",
    "power_grid",
    "solve_partition",
    "ENERGY_TOLERANCE",
]

K0 = 2.0 * math.pi  # wavenumber in units of 1/lambda
#: estimated power error of a windowed current (beam.window_bias) above which check_taper warns
TAPER_TOLERANCE = 0.01


class MoMAccuracyWarning(UserWarning):
    """The MoM set-up is outside the range where its answer can be trusted."""


# ---------------------------------------------------------------------------
# Surface (Fung & Chen 1985 spectral method)
# ---------------------------------------------------------------------------

def gaussian_surface(length_wl, n_points, rms_height_wl, corr_length_wl, seed=0, second_derivative=False):
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
        exact slope of the band-limited surface; with ``second_derivative=True`` also
        d2fdx2, its exact curvature f'' (1/wavelength).
    """
    length_wl = float(length_wl)
    n_points = int(n_points)
    dx = length_wl / n_points
    x = (np.arange(n_points) + 0.5) * dx
    if rms_height_wl == 0.0:
        zero = np.zeros(n_points)
        return (x, zero, zero.copy(), zero.copy()) if second_derivative else (x, zero, zero.copy())
    dk = 2.0 * math.pi / length_wl
    j_max = int(math.ceil(12.0 / corr_length_wl / dk))
    if 2 * j_max >= n_points:
        raise UsageError(
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
    if not second_derivative:
        return x, f, dfdx
    X[: j_max + 1] *= 1j * kj
    return x, f, dfdx, np.fft.irfft(X, n=n_points)


# ---------------------------------------------------------------------------
# Eqs. 18-20: the EFIE moment matrix and the incident field
# ---------------------------------------------------------------------------

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
        raise UsageError(f"pts_per_wl must be >= 2 (the pulses cannot represent a wave below that), got {pts_per_wl}")
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


def check_taper(theta_i, w, partition_length, pols=("s",), beam=None, eta=None):
    """Warn when the Gaussian taper (Eq. 22) would bias the power by more than TAPER_TOLERANCE, or is too wide.

    A windowed current (plane-wave incidence, ``beam`` False) reflects, off a flat PEC, the power ratio
    :func:`hyde_bsdf.mom.beam.window_bias` -- measured and exact: s 1 + 0.82 tau, p 1 - 0.26 tau at Thorsos'
    tau = (1 + 2 tan^2 ti)/(k w cos ti)^2 = 0.02 (1 + 0.76 tau and 1 - 0.25 tau as tau -> 0); the warning gives
    that estimate per polarisation wherever it exceeds the tolerance, or where the window's spectrum (3/(k w) in
    sin theta) crosses grazing.  A finite index (``eta``) takes the s law for p too: measured on flat plates at
    tau = 0.0195, 80 and 85 deg, glass p +1.1 / +1.5 % and Infragold p +2.2 / +1.4 % (s +1.5 to +1.9 %) where the
    s law says +1.6 % (the PEC's p law, -0.5 %, would understate them).  A Gaussian beam (``beam`` True,
    :mod:`hyde_bsdf.mom.beam`) has no such bias (flat PEC plate: 1.0000 in p, 1.0026 in s at 10 pts/lambda, the
    sampling; glass and Infragold within 0.26 %).  On a rough surface the law is a lower bound (Fig. 6 statistics
    at 70 deg, w = 37.5: +2.2 % in s where it says +0.2 %; the beam +0.2 %): the energy check after the solve
    (ENERGY_TOLERANCE) catches what it misses.  ``beam``: bool per theta_i.
    """
    reasons = []
    lit = np.zeros(np.size(theta_i), bool) if beam is None else np.asarray(beam, bool)
    for ti, by_beam in zip(np.atleast_1d(theta_i), lit):
        if by_beam:
            continue
        est = {pol: float(window_bias(ti, w, pol if eta is None else "s")[0]) - 1.0 for pol in pols}
        beyond = math.sin(ti) + 3.0 / (K0 * w) >= 1.0
        if max(abs(e) for e in est.values()) > TAPER_TOLERANCE or beyond:
            reasons.append(f"taper too narrow for theta_i={math.degrees(ti):.1f} deg: the windowed current of "
                           f"w={w:.3g} wavelengths has an estimated power error of "
                           + ", ".join(f"{pol} {100 * e:+.2g} %" for pol, e in est.items())
                           + f" ({'flat-PEC law' if eta is None else 'flat-plate s law'}; tolerance "
                           f"{100 * TAPER_TOLERANCE:g} %"
                           + ("; its spectrum crosses grazing, where the law understates the error" if beyond else "")
                           + "): use incidence='beam' or a wider taper (taper_width_wl, longer partitions)")
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

#: a dense fallback may cost at most this many times the fast solver's own estimate (or its time spent)
DENSE_FALLBACK_RATIO = 10.0


def _memory_available():
    """Bytes the MoM may plan with: :func:`hyde_bsdf.resources.available_memory`, or 8 GiB if unknown."""
    return resources.available_memory() or 8 * 2**30


def _dense_cost(n, pols, eta):
    """(bytes, CPU seconds) of a dense solve of n unknowns (:mod:`hyde_bsdf.mom.dense`; the time model is
    :func:`hyde_bsdf.resources.dense_solve_cost`)."""
    seconds = resources.dense_solve_cost(n, len(pols), 1 if eta is None else 2, eta is not None and eta.imag == 0)
    return _matrices_per_partition(pols, eta) * 16.0 * n * n, seconds


def _dense_refusal(n, pols, eta, fast_seconds):
    """Why a dense fallback of n unknowns is refused (memory, or more than DENSE_FALLBACK_RATIO x the fast
    solver's cost), or None where it may run."""
    need, seconds = _dense_cost(n, pols, eta)
    free = _memory_available()
    if need > 0.8 * free:
        return (f"a dense LU of {n} unknowns needs {resources.format_bytes(need)}, more than the "
                f"{resources.format_bytes(free)} available")
    if seconds > DENSE_FALLBACK_RATIO * fast_seconds:
        return (f"a dense LU of {n} unknowns would take ~{seconds:.0f} CPU s, more than {DENSE_FALLBACK_RATIO:g}x "
                f"the fast solver's ~{fast_seconds:.1f} s")
    return None


def _solve_fields(task, psi, clock):
    """Stage 3 of a partition: the surface fields u, v by the chosen method, with the fast solver's fallbacks.

    The fast solver falls back on its own to GMRES (the fast operator, preconditioned by its strong part);
    a dense LU follows only where that too misses the tolerance and the LU is affordable
    (:func:`_dense_refusal`); otherwise the result keeps the residual reached, with a reason naming ``tol``.
    Returns (fields dict with ``u_P``, ``v_P``; times (fill, factor, solve); method used;
    reasons: every fallback with why).
    """
    x, y, fp, fpp, dx = task["x"], task["y"], task["dfdx"], task["d2fdx2"], task["dx"]
    pols, eta = task["pols"], task["eta"]
    check_finite_surface(x, y, fp, fpp, psi)
    if task.get("solver", "dense") != "fast":
        return solve_dense(x, y, fp, fpp, dx, psi, pols, eta, clock), "dense", []
    reasons = []
    tol = task.get("tol") or FAST_TOL
    t0 = clock()
    try:
        sol = solve_fast(x, y, fp, fpp, dx, psi, pols, eta, tol=tol, method=task.get("fast_method", "fb"))
    except FastSolverUnsuitable as exc:
        why = None if task.get("dense_ok", True) else "the memory available"
        why = why or _dense_refusal(x.size, pols, eta, resources.COSTS.fast_seconds_per_unknown * x.size)
        if why:
            raise UsageError(f"the fast solver cannot take this surface ({exc}) and {why}: use shorter partitions "
                             "(more `partitions`) or a smoother surface") from None
        reasons.append(f"fast solver unsuitable ({exc}): dense LU instead")
    else:
        info = sol["info"]
        reasons += info["reasons"]
        worst = max(float(np.max(info[p]["residual"])) for p in pols)
        spent = clock() - t0
        why = None if info["converged"] else (
            "the memory available" if not task.get("dense_ok", True) else
            _dense_refusal(x.size, pols, eta, max(spent, resources.COSTS.fast_seconds_per_unknown * x.size)))
        if info["converged"] or why:
            if not info["converged"]:
                reasons.append(f"fast solver stopped at residual {worst:.2g} > tolerance {tol:g} and {why}: the "
                               "result carries that residual (raise `tol`, or use shorter partitions)")
            t = info["times"]
            sol["times"] = (t["setup"], 0.0, t["solve"])
            sol["residual"] = worst
            return sol, "fast", reasons
        reasons.append(f"fast solver did not converge (residual {worst:.2g} > tolerance {tol:g}): dense LU instead")
    t_lost = clock() - t0          # the fallback's time is counted from the fast attempt on
    sol = solve_dense(x, y, fp, fpp, dx, psi, pols, eta, clock)
    f, fa, so = sol["times"]
    sol["times"] = (f + t_lost, fa, so)
    return sol, "dense", reasons


def _radiate(task, fields, out, lit=None):
    """Stage 4 of a partition: taper (Eq. 22), absorbed power, far field (Eq. 21) of every polarisation.

    ``lit``: (flux, effective length) of the beam-lit incidence angles (``task["beam"]``, :mod:`beam`), whose
    currents are not windowed; ``out["length"]`` [n_ti] is the effective illuminated length that normalises sigma.
    """
    x, y, fp, dx = task["x"], task["y"], task["dfdx"], task["dx"]
    pols, eta = task["pols"], task["eta"]
    n_ti = np.atleast_1d(task["theta_i"]).size
    win = np.repeat(taper(x, 0.0, task["w"])[:, None], n_ti, axis=1)
    out["flux"] = incident_flux(x, fp, dx, win[:, 0], task["theta_i"])
    out["length"] = np.full(n_ti, task["w"] * math.sqrt(math.pi / 2.0))
    if lit is not None:
        beam = task["beam"]
        win[:, beam] = 1.0
        out["flux"][beam], out["length"][beam] = lit
    Us, Vs = [], []
    for pol in pols:
        u, v = fields["u_" + pol], fields["v_" + pol]
        out["absorbed_" + pol] = np.zeros(n_ti) if eta is None else absorbed_flux(u, v, win, dx)
        Us.append(np.zeros((x.size, n_ti), complex) if u is None else u * win)
        Vs.append(np.zeros((x.size, n_ti), complex) if v is None else v * win)
    # one far-field pass for all polarisations and both angle grids (the kernel e^{jk(x sin + y cos)} and
    # the segments' Fourier coefficients are shared; a PEC's zero u or v columns are skipped)
    U, V = np.hstack(Us), np.hstack(Vs)
    if eta is None:
        U = U if "p" in pols else None
        V = V if "s" in pols else None
    F, Ff = far_field_uv(x, y, fp, dx, U, V, [task["theta_r"], task["theta_fine"]])
    for i, pol in enumerate(pols):
        out["F_" + pol] = F[i * n_ti:(i + 1) * n_ti]
        out["Ffine_" + pol] = Ff[i * n_ti:(i + 1) * n_ti]


def solve_partition(task):
    """Solve one partition: surface fields by the dense or fast method, taper, radiate.

    ``task`` is a dict with x, y, dfdx, d2fdx2 (local coordinates, centred on the
    partition), dx, theta_i [rad], theta_r [rad], theta_fine [rad] (the power
    grid), w, pols (tuple of "s"/"p"), eta (None for a PEC, else n - j kappa) and
    optionally solver ("dense" or "fast"), tol (the fast solver's residual) and dense_ok
    (whether the fast solver may fall back to a dense LU).
    Returns a dict with, per polarisation P, the far fields ``F_P``
    [n_ti, n_tr] and ``Ffine_P`` [n_ti, n_fine] (the F of :mod:`hyde_bsdf.mom.kernels`),
    the absorbed flux ``absorbed_P`` [n_ti], the incident ``flux`` [n_ti], the method that
    solved it (``solver``), the fast solver's fallbacks (``reasons``) and the CPU seconds
    (process time) of each stage (fill, factor, solve, far field).
    """
    clock = time.process_time  # CPU seconds of this process (its BLAS is single-threaded in the pool)
    psi = incident_field(task["x"], task["y"], task["theta_i"])
    beam = task.get("beam")
    lit = None
    if beam is not None and np.any(beam):
        pb, fb, lb = gaussian_beam(task["x"], task["y"], task["dfdx"], task["dx"],
                                   np.atleast_1d(task["theta_i"])[beam], task["w"])
        psi[:, beam] = pb
        lit = (fb, lb)
    fields, method, reasons = _solve_fields(task, psi, clock)
    tc = clock()
    out = {"solver": method, "reasons": reasons, "residual": fields.get("residual")}
    _radiate(task, fields, out, lit)
    fill, factor, solve = fields["times"]
    out["times"] = np.array([fill, factor, solve, clock() - tc])
    return out


class SerialExecutor(cf.Executor):
    """A concurrent.futures.Executor that runs each task at once in the calling process.

    For small problems (tests), where starting a process pool costs more than the work.
    """

    def submit(self, fn, /, *args, **kwargs):
        fut = cf.Future()
        # one BLAS thread while the task runs: threaded BLAS only slows down these matrix sizes
        # (the 2-thread LU of a 500-unknown partition is 10x slower here) -- restored afterwards
        previous = limit_blas_threads(1)
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # hand the error to the caller through the future
            fut.set_exception(exc)
        finally:
            restore_blas_threads(previous)
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
    polarization : tuple of the polarisations solved, ("s",), ("p",) or ("s", "p").
    sigma : ndarray [n_ti, n_tr], Eq. 23 (dimensionless: 2-D RCS per effective
        illuminated length), coherent plus incoherent, of the first polarisation.
    sigma_s, sigma_p : the same per polarisation (None where not solved).
    sigma_sp : complex ndarray, the cross term <E_s E_p*> in the same units (None
        unless both were solved); E_p in the right-handed (s, p, k) basis of
        :mod:`hyde_bsdf.model.fresnel` (a flat PEC has sigma_sp = -sigma_s).
    mueller : dict "M00", "M01", "M22", "M23" of ndarrays [n_ti, n_tr] (both
        polarisations only, else None): M00 = (sigma_s + sigma_p)/2,
        M01 = (sigma_s - sigma_p)/2, M22 = Re sigma_sp, M23 = Im sigma_sp -- the
        in-plane Mueller matrix [[M00, M01, 0, 0], [M01, M00, 0, 0], [0, 0, M22, M23],
        [0, 0, -M23, M22]] in the units of sigma, with the model's conventions.
    mueller_std_error : dict of the same keys, standard errors over partitions.
    mueller_normalised, mueller_normalised_std_error : dicts "M01/M00", "M22/M00",
        "M23/M00" (ratios of the partition means; jackknife standard errors).
    sigma_coherent, sigma_incoherent : first polarisation, the split |<F>|^2 / rest.
    power_balance : ndarray [n_ti], reflected / incident power of the first
        polarisation: the far-field power of the windowed fields over the incident
        power through the windowed surfaces (:func:`incident_flux`, the partitions' tilt included).
    power_balance_s, power_balance_p : the same per polarisation (None where not solved).
    absorbed_s, absorbed_p : power flowing into the surface (Poynting's theorem on the
        surface fields, :func:`hyde_bsdf.mom.kernels.absorbed_flux`) over the same
        incident power: 0 for a PEC, the absorbed (metal) or transmitted (glass) share.
    energy_s, energy_p : reflected + absorbed (1 when energy is conserved).
    power_balance_nominal : ndarray [n_ti], the first polarisation's reflected power over
        the nominal incident power of Eq. 23, (1/(2 pi cos ti)) int sigma d tr; it carries
        the sample's tilt noise, ~ tan(ti) sqrt(2) sigma_h / (w sqrt(pi/2) sqrt(M)).
    power_coherent : ndarray [n_ti], the coherent (specular) share of the nominal power.
    fine_theta_r, fine_sigma : the internal power grid (:func:`power_grid`) and sigma on
        it (first polarisation); fine_sigma_s, fine_sigma_p per polarisation.
    sigma_std_error : ndarray [n_ti, n_tr], standard error of sigma from the
        spread between partitions (the speckle left by a finite M); sigma_s_std_error,
        sigma_p_std_error per polarisation.
    times : dict of summed worker CPU seconds (process time) per stage ("fill",
        "factor", "solve", "far_field") and the wall time of the call ("wall").
    params : dict of the run's parameters (taper width w, dx, N per partition, index, ...).
    warnings : list of str, the MoM failure reasons found for this run.
    floor_s, floor_p : ndarray [n_ti, n_tr], the estimated floor of sigma_s / sigma_p set by the truncated
        partition, the windowed current's surface waves (s) and the solver's tolerance
        (:func:`hyde_bsdf.mom.floor.partition_floor`; None where not solved).
    valid_s, valid_p : bool ndarray [n_ti, n_tr], sigma >= FLOOR_MARGIN (20) x the floor: within about 2.5 dB
        of what an untruncated partition gives; ``valid`` the same for the first polarisation.
    floor_reason : str, why a sigma flagged invalid is not the surface's (for legends and summaries).
    atlas_verdict : dict (a property, computed when first read): the accuracy atlas's verdict on the model at
        this run's geometry, :func:`hyde_bsdf.model.accuracy.verdict` (``["summary"]``: one line).
    partition_fields : dict "s" / "p" of complex ndarrays [M, n_ti, n_tr]: each partition's far field on
        ``theta_r``, scaled so that ``sigma_P = mean(|F|^2, axis=0)`` (and sigma_sp = mean(F_s conj(F_p))) --
        what any other statistic over partitions (coherent Mueller elements, a jackknife) needs.
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
    polarization: tuple = ("s",)
    sigma_s: np.ndarray = None
    sigma_p: np.ndarray = None
    sigma_sp: np.ndarray = None
    sigma_s_std_error: np.ndarray = None
    sigma_p_std_error: np.ndarray = None
    fine_sigma_s: np.ndarray = None
    fine_sigma_p: np.ndarray = None
    power_balance_s: np.ndarray = None
    power_balance_p: np.ndarray = None
    absorbed_s: np.ndarray = None
    absorbed_p: np.ndarray = None
    energy_s: np.ndarray = None
    energy_p: np.ndarray = None
    mueller: dict = None
    mueller_std_error: dict = None
    mueller_normalised: dict = None
    mueller_normalised_std_error: dict = None
    floor_s: np.ndarray = None
    floor_p: np.ndarray = None
    valid_s: np.ndarray = None
    valid_p: np.ndarray = None
    valid: np.ndarray = None
    floor_reason: str = ""
    partition_fields: dict = None

    @property
    def theta_i_deg(self):
        return np.degrees(self.theta_i)

    @functools.cached_property
    def atlas_verdict(self):
        """The accuracy atlas's verdict on the model (V-groove, the paper's diffuse term) at this run's geometry:
        :func:`hyde_bsdf.model.accuracy.verdict` at each theta_i for the run's rms slope, height and index -- how
        far the model may be from this very kind of result, and the cheapest adequate variant (``["summary"]``,
        one line; ``["per_angle"]``).  Computed when first read."""
        from hyde_bsdf.model.accuracy import verdict

        p = self.params
        if not p.get("rms_height_wl"):
            return {"per_angle": [], "answers": [], "summary": "accuracy atlas: not applicable (a flat surface)"}
        return verdict(self.theta_i, p["rms_slope"], p["n"], p["k"], sigma_h_wl=p["rms_height_wl"])

    @property
    def theta_r_deg(self):
        return np.degrees(self.theta_r)


def _check_positive(name, value, allow_zero=False):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise UsageError(f"{name} must be a real number, got {value!r}") from None
    ok = math.isfinite(v) and (v >= 0.0 if allow_zero else v > 0.0)
    if not ok:
        raise UsageError(f"{name} must be finite and {'>= 0' if allow_zero else '> 0'}, got {value!r}")
    return v


def process_pool(max_workers=None, start_method=None):
    """The default executor: a process pool whose workers each run single-threaded BLAS.

    One worker per core (``os.cpu_count()``) unless ``max_workers`` says otherwise;
    one BLAS thread per worker, since the partitions already keep every core busy.
    ``start_method``: "fork" (the default on Linux) or "spawn" (elsewhere; and for a caller whose
    process runs threads that a fork would copy mid-work, e.g. Dr.Jit's: the inverse's tiles).
    """
    workers = max(1, int(max_workers or os.cpu_count() or 1))
    ctx = multiprocessing.get_context(start_method or ("fork" if sys.platform.startswith("linux") else "spawn"))
    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=worker_init)


def _progress_reporter(total, progress):
    """``update(done)`` reporting partitions done through :mod:`hyde_bsdf.progress` (a callback, True: stderr lines,
    None: stderr lines for runs of 10 or more partitions, False: nothing), at most every PROGRESS_SECONDS."""
    callback = as_callback(total >= 10 if progress is None else progress, prefix="mom:")
    throttle = Throttle(callback)

    def update(done):
        def line():
            t = throttle.elapsed
            return f"partition {done}/{total}, {t:.1f} s elapsed, ~{t / done * (total - done):.0f} s left"
        throttle(line, force=done == total and throttle.elapsed >= 1.0)

    return update


def _check_seed(seed):
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UsageError(f"seed must be an integer >= 0, got {seed!r}")
    return int(seed)


def _check_polarization(polarization):
    pols = (polarization,) if isinstance(polarization, str) else tuple(polarization)
    if not pols or any(p not in ("s", "p") for p in pols) or len(set(pols)) != len(pols):
        raise UsageError(f"polarization must be 's', 'p' or a sequence of both, e.g. ('s', 'p'), got {polarization!r}")
    return pols


def _check_index(n, k):
    """The paper's eta = n - j k the solver works with (the boundary of :class:`Index`'s spelling),
    None for the PEC (n=None); n > 0, k >= 0, both in NATURAL_INDEX."""
    if n is not None:
        n = _check_positive("n", n)
        k = None if k is None else _check_positive("k", k, allow_zero=True)
        if not (NATURAL_INDEX.contains(n) and (k is None or NATURAL_INDEX.contains(k))):
            raise UsageError(f"n and k must be <= {NATURAL_INDEX.hi:g} (use the PEC, n=None, for a better "
                             f"conductor), got n={n:g}, k={k or 0.0:g}")
    return Index.from_keywords(n, k, pec_if_missing=True, n_range=NATURAL_INDEX, k_range=NATURAL_INDEX).paper_eta()


def _matrices_per_partition(pols, eta):
    """Complex N x N arrays a worker holds at its peak (fill + LU)."""
    if eta is not None:
        return 7
    return 2 + (len(pols) > 1)


#: |reflected + absorbed - 1| beyond this after a solve gives a MoMAccuracyWarning with the value: the stated
#: tolerance of the power balance (the partitions' tilt is divided out by incident_flux; check_taper warns before
#: the solve where the windowed current's own bias exceeds TAPER_TOLERANCE)
ENERGY_TOLERANCE = 0.01
#: fewest points per wavelength of *arc length* at the steepest point of the realised surface
ARC_PTS_MIN = 5.0
#: largest turn of the surface direction over one cell (radians), |f''| dx / (1 + f'^2)
TURN_MAX = 0.3
#: most unknowns per partition: a dense 10,000 x 10,000 LU is ~10 CPU minutes per partition and 1.6 GB
MAX_UNKNOWNS = 10000
#: most quadrature panels per cell for the interior Green's function (one per decay length)
MAX_PANELS = 64


@dataclass(frozen=True)
class MoMOptions(Options):
    """How :func:`scatter` samples, solves and runs (each field is also a keyword of :func:`scatter`;
    its docstring describes them)."""

    pts_per_wl: float = 10
    seed: int = 0
    taper_width_wl: float | None = None
    solver: str = "auto"
    tol: float | None = None
    incidence: str = "auto"
    executor: object = None
    timeout: float | None = None
    progress: object = None


def scatter(length_wl, partitions, rms_height_wl, corr_length_wl, theta_i_deg, theta_r_deg, *,
            polarization="s", n=None, k=None, options: MoMOptions | None = None, **settings):
    """Incoherent far-field scattering of a 1-D Gaussian rough surface -- paper Eqs. 18-23, both polarisations.

    The sampling, the solver and the executor are a :class:`MoMOptions` (``options``), or its fields
    given as keywords (``pts_per_wl=8, executor=...``).

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
    pts_per_wl : float, samples per wavelength along x (default 10).  Where the
        realised surface is so steep that this leaves fewer than ARC_PTS_MIN = 5
        per wavelength of arc length (or turns by more than TURN_MAX = 0.3 rad per
        cell), the surface is resampled finer (``params["pts_per_wl"]`` says how
        fine); if that does not fit in memory a ValueError is raised.
    seed : int >= 0, surface realisation (same seed, same surface at any pts_per_wl,
        for both polarisations and any index).
    executor : concurrent.futures.Executor or None.  None: a process pool with
        one worker per core (each worker single-threaded BLAS); pass
        :class:`SerialExecutor` for in-process runs or a dask executor
        (``distributed.Client(...).get_executor()``) to spread partitions across
        machines.  A caller's executor is not shut down.  The wait on it never hangs:
        a dask cluster that loses its last worker (for ``gather.NO_WORKER_GRACE_S`` =
        60 s), a closed client or a broken process pool ends in :class:`ExecutorError`
        naming it, and a ``progress`` line reports every 30 s in which no partition finished.
    taper_width_wl : float in (0, L_p], Eq. 22's w (default L_p / 4); with the beam, its
        footprint (the incident field's e^-(x/w)^2 on the mean plane).
    progress : callable progress(message), bool or None (:mod:`hyde_bsdf.progress`): a
        line "partition done/total, elapsed, left" at most every 3 s; True: on stderr; None: on stderr
        for runs of 10 or more partitions; False: none.  The wait's heartbeat (every 30 s without a finished
        partition) goes to the callback too (None: on stderr).
    polarization : "s", "p" or ("s", "p") (default "s").  s: E along z
        (TM_z, the paper's Fig. 6); p: H along z.  Both on the same surface give
        the cross term and the in-plane Mueller matrix.
    timeout : float or None: seconds without any partition finishing
        after which the run is given up with :class:`ExecutorError` (None: no limit
        while the executor is alive).
    n, k : float or None: the paper's complex index eta = n - j k
        (n > 0, k >= 0; Infragold 0.285, 7.3523).  Neither: a perfect conductor.
    solver : "auto", "dense" or "fast".  "dense": one LU of the full matrix
        per polarisation (:mod:`hyde_bsdf.mom.dense`, at most MAX_UNKNOWNS per partition);
        "fast": forward-backward sweeps with spectral acceleration (:mod:`hyde_bsdf.mom.fast`,
        O(N) memory, up to MAX_FAST_UNKNOWNS), GMRES where the sweeps diverge or stall and
        the dense LU where that fails too, each fallback a MoMAccuracyWarning naming why;
        "auto" (default): fast from AUTO_FAST_UNKNOWNS unknowns per partition on, and
        wherever the dense path would be refused, if the surface suits it (its height
        range against the partition length), else dense.  ``params["solver"]`` says which ran.
    tol : float or None: the fast solver's relative residual
        ||b - A x|| / ||b|| (default ``fast.FAST_TOL`` = 1e-4; 1e-3 is within 0.01 dB).
    incidence : "auto", "window" or "beam".  "window": the paper's plane wave with the
        current windowed by Eq. 22; "beam": an exact Gaussian beam of footprint w, unwindowed currents
        (:mod:`hyde_bsdf.mom.beam`: no power bias, no forward-grazing floor in s); "auto" (default): the
        beam for theta_i >= BEAM_FROM_DEG = 80 deg, the window below.  ``params["incidence"]`` per theta_i.

    Returns
    -------
    MoMResult with ``theta_r`` [rad], ``sigma`` [n_theta_i, n_theta_r] (Eq. 23),
    per-polarisation ``sigma_s``/``sigma_p``, ``sigma_sp``, ``mueller``, the power
    balance, absorbed power and energy per polarisation (see :class:`MoMResult`).

    Raises
    ------
    ValueError naming the parameter for bad input, for sampling too coarse to be
    repaired, and before any allocation that would not fit in memory.
    ExecutorError (a RuntimeError, one line naming the executor) when the executor
    dies, breaks or exceeds ``timeout``; the pending partitions are cancelled.

    Warns
    -----
    MoMAccuracyWarning where the MoM answer cannot be trusted (see module docstring),
    and after every solve whose reflected + absorbed power is off 1 by more than
    ENERGY_TOLERANCE (the value is in the message).
    """
    t_wall = time.perf_counter()
    opts = MoMOptions.of(options, settings, "scatter")
    cfg = _check_inputs(length_wl, partitions, rms_height_wl, corr_length_wl, theta_i_deg, theta_r_deg,
                        polarization, n, k, opts)
    cfg["beam"] = _check_incidence(opts.incidence, cfg["ti_deg"])
    executor, progress = opts.executor, opts.progress
    own = check_executor(executor) is None
    workers = min(os.cpu_count() or 1, cfg["partitions"]) if own else 1
    surf = _realise_surface(cfg, workers)
    for r in surf["reasons"]:
        warnings.warn("MoM failure risk: " + r, MoMAccuracyWarning, stacklevel=2)
    _report_estimate(cfg, surf, workers if own else _executor_workers(executor), progress)
    tasks = _partition_tasks(cfg, surf)
    del surf["x"], surf["f"], surf["s"], surf["c"]
    results = _solve_partitions(tasks, executor, workers, cfg, progress)
    del tasks
    for r in _solver_reasons(results):
        warnings.warn("MoM solver fallback: " + r, MoMAccuracyWarning, stacklevel=2)
    stats = _statistics(results, cfg, surf)
    post = _energy_check(stats["per"], cfg)
    for r in post:
        warnings.warn("MoM failure: " + r, MoMAccuracyWarning, stacklevel=2)
    return _result(cfg, surf, results, stats, surf["reasons"] + _solver_reasons(results) + post,
                   time.perf_counter() - t_wall)


def estimate(length_wl, partitions, rms_height_wl, corr_length_wl, theta_i_deg, theta_r_deg, *,
             polarization="s", n=None, k=None, workers=None, options: MoMOptions | None = None, **settings):
    """What :func:`scatter` with these arguments will cost, without solving anything.

    The surface is realised (as ``scatter`` would: same seed, same resampling, same solver choice), then the cost
    model of :mod:`hyde_bsdf.mom.cost` gives the CPU seconds per partition.  ``options``/``settings``: as
    :func:`scatter`'s (a :class:`MoMOptions` or its fields as keywords).  ``workers``: the processes the
    partitions are spread over (default: one per core, at most one per partition).  Returns a dict: ``cpu_seconds``
    (all partitions), ``wall_seconds`` (over the workers), ``memory_bytes`` (peak, all workers) and
    ``memory_text``, ``unknowns`` per partition, ``method``, ``partitions``, ``workers``, ``n_rhs``, ``n_far``,
    ``features`` (the model's inputs) and ``line`` (the sentence ``scatter`` prints before a long run).
    Raises what ``scatter`` raises for bad arguments or a run that would not fit in memory.
    """
    opts = MoMOptions.of(options, settings, "estimate")
    cfg = _check_inputs(length_wl, partitions, rms_height_wl, corr_length_wl, theta_i_deg, theta_r_deg,
                        polarization, n, k, opts)
    cfg["beam"] = _check_incidence(opts.incidence, cfg["ti_deg"])
    workers = max(1, min(int(workers or os.cpu_count() or 1), cfg["partitions"]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MoMAccuracyWarning)
        surf = _realise_surface(cfg, workers)
    return _estimate(cfg, surf, workers)


def _estimate(cfg, surf, workers):
    """The cost model applied to a realised surface (``_realise_surface``'s dict): see :func:`estimate`."""
    n, dx, part_len, eta, pols = surf["n_part"], surf["dx"], cfg["part_len"], cfg["eta"], cfg["pols"]
    height = float(np.max(np.ptp(surf["f"].reshape(cfg["partitions"], n), axis=1))) if cfg["rough"] else 0.0
    stretch = float(np.max(np.hypot(1.0, surf["s"]))) if cfg["rough"] else 1.0
    feats = _cost.partition_features(n, dx, height, part_len, eta, stretch, surf["method"])
    n_rhs = cfg["ti_deg"].size * len(pols)
    n_far = cfg["theta_r"].size + surf["fine"].size
    if feats["method"] == "fast":
        per = sum(_cost.fast_seconds(feats, n_rhs, n_far))
        try:
            need = _fast_bytes(n, dx, height, part_len, eta)
        except FastSolverUnsuitable:
            need = _dense_cost(n, pols, eta)[0]
    else:
        need, per = _dense_cost(n, pols, eta)
        per += _cost.fast_seconds(dict(feats, block=0, waves=0, panels=0), n_rhs, n_far)[2]
    total = per * cfg["partitions"]
    memory = need * workers + resources.COSTS.surface_bytes_per_point * n * cfg["partitions"]
    share = _cost.core_share(workers)
    est = dict(cpu_seconds=total, wall_seconds=per * math.ceil(cfg["partitions"] / workers) / share,
               core_share=share, memory_bytes=memory,
               memory_text=resources.format_bytes(memory), unknowns=n, method=feats["method"], partitions=cfg["partitions"], workers=workers, n_rhs=n_rhs, n_far=n_far,
               features=feats)
    est["line"] = _cost.describe(est)
    return est


def _executor_workers(executor):
    """How many workers a caller's executor spreads the partitions over (1 where it cannot tell)."""
    count = getattr(executor, "_max_workers", None)
    if count:
        return int(count)
    client = getattr(executor, "_client", None)
    try:
        return max(1, len(client.scheduler_info()["workers"])) if client is not None else 1
    except Exception:  # noqa: BLE001 -- an estimate's worker count is advice; one worker is the safe guess
        return 1


def _report_estimate(cfg, surf, workers, progress):
    """Before a run expected to take more than cost.REPORT_SECONDS: its estimated time and memory, one line through
    the progress callback (None: stderr, as the wait's heartbeat; False: nothing)."""
    report = as_callback(True if progress is None else progress, prefix="mom:")
    if report is None:
        return
    est = _estimate(cfg, surf, max(1, min(workers, cfg["partitions"])))
    if est["wall_seconds"] > _cost.REPORT_SECONDS:
        report(est["line"])


# ---------------------------------------------------------------------------
# The stages of scatter: checks, surface, per-partition solve, statistics, energy
# ---------------------------------------------------------------------------

#: "auto" takes the fast solver from this many unknowns per partition on (the Fig. 6 partitions have 1500)
AUTO_FAST_UNKNOWNS = 1000
#: most unknowns per partition for the fast solver
MAX_FAST_UNKNOWNS = 200000


#: incidence="auto" lights theta_i at and above this (degrees) with the Gaussian beam (:mod:`hyde_bsdf.mom.beam`)
BEAM_FROM_DEG = 80.0


def _check_incidence(incidence, ti_deg):
    """Per theta_i, whether the beam (True) or the windowed plane-wave current (False) lights it."""
    if incidence not in ("window", "beam", "auto"):
        raise UsageError(f"incidence must be 'window', 'beam' or 'auto', got {incidence!r}")
    if incidence == "auto":
        return ti_deg >= BEAM_FROM_DEG
    return np.full(ti_deg.size, incidence == "beam")


def _check_inputs(length_wl, partitions, rms_height_wl, corr_length_wl, theta_i_deg, theta_r_deg, polarization, n,
                  k, opts):
    """Stage 1: every argument checked (ValueError naming it), the partition geometry and the taper."""
    pts_per_wl, seed, taper_width_wl, timeout, solver, tol = (opts.pts_per_wl, opts.seed, opts.taper_width_wl,
                                                               opts.timeout, opts.solver, opts.tol)
    length_wl = _check_positive("length_wl", length_wl)
    if isinstance(partitions, bool) or not isinstance(partitions, (int, np.integer, float)) \
            or int(partitions) != partitions or partitions < 1:
        raise UsageError(f"partitions must be an integer >= 1, got {partitions!r}")
    partitions = int(partitions)
    rms_height_wl = _check_positive("rms_height_wl", rms_height_wl, allow_zero=True)
    corr_length_wl = _check_positive("corr_length_wl", corr_length_wl)
    pts_per_wl = _check_positive("pts_per_wl", pts_per_wl)
    seed = _check_seed(seed)
    pols = _check_polarization(polarization)
    eta = _check_index(n, k)
    if timeout is not None:
        timeout = _check_positive("timeout", timeout)
    if solver not in ("auto", "dense", "fast"):
        raise UsageError(f"solver must be 'auto', 'dense' or 'fast', got {solver!r}")
    if tol is not None:
        tol = _check_positive("tol", tol)
        if not 1e-12 <= tol <= 0.1:
            raise UsageError(f"tol must be in [1e-12, 0.1] (the fast solver's relative residual), got {tol!r}")
    ti_deg = np.atleast_1d(np.asarray(theta_i_deg, dtype=float))
    tr_deg = np.atleast_1d(np.asarray(theta_r_deg, dtype=float))
    if ti_deg.ndim != 1 or not np.all(np.isfinite(ti_deg)) or np.any(ti_deg < 0) or np.any(ti_deg >= 90):
        raise UsageError(f"theta_i_deg must be finite angles in [0, 90) degrees, got {theta_i_deg!r}")
    if tr_deg.ndim != 1 or not np.all(np.isfinite(tr_deg)) or np.any(np.abs(tr_deg) > 90):
        raise UsageError(f"theta_r_deg must be finite signed angles in [-90, 90] degrees, got {theta_r_deg!r}")
    part_len = length_wl / partitions
    n_part = int(round(part_len * pts_per_wl))
    if n_part < 4:
        raise UsageError(f"partitions of {part_len:g} wavelengths at pts_per_wl={pts_per_wl:g} hold fewer than 4 pulses")
    if taper_width_wl is None:
        w = part_len / 4.0
    else:
        w = _check_positive("taper_width_wl", taper_width_wl)
        if w > part_len:
            raise UsageError(f"taper_width_wl={w:g} must be in (0, {part_len:g}] (the partition length "
                             f"length_wl/partitions; Eq. 22's window must fit in its partition)")
    return dict(length_wl=length_wl, partitions=partitions, rms_height_wl=rms_height_wl,
                corr_length_wl=corr_length_wl, pts_per_wl=pts_per_wl, seed=seed, pols=pols, eta=eta,
                timeout=timeout, solver=solver, tol=tol, ti_deg=ti_deg, theta_i=np.radians(ti_deg),
                theta_r=np.radians(tr_deg), rough=rms_height_wl > 0.0, part_len=part_len, n_part=n_part, w=w)


def _fast_block_wl(height_wl, eta):
    """The fast solver's block length for a partition of this height range (glass's interior k sets it)."""
    return block_length_wl(height_wl, [K0] if eta is None or eta.imag != 0 else [K0, K0 * eta])


def _fast_bytes(n, dx, height, part_len, eta):
    """Peak bytes of one fast solve: plane-wave factors (Q per sample and direction, every region with a far part),
    the strong part's band, the block matrices.  O(N Q); the blocks and Q from fast.plan_blocks itself (what
    solve_fast will use: glass' interior k has its own rule).  Raises FastSolverUnsuitable."""
    ks = [K0] if eta is None or eta.imag != 0 else [K0, K0 * eta]
    b, rules = plan_blocks(n, dx, height, part_len, ks, NEAR_WL)
    q = sum(phi.size for phi, _ in rules)
    nk = 1 if eta is None else 2
    planes = q * (7 + 8)                                   # 7 kept per region, ~8 temporaries while set up
    bands = (4 * b + 3) * (2 if eta is None else 4)
    return 16.0 * n * (planes + 1.5 * bands + 6 * nk * nk * b + 40)


def _choose_solver(cfg, npart, dx, height, workers, budget, why):
    """The method for partitions of npart unknowns, or a ValueError naming why neither fits."""
    part_len, pols, eta = cfg["part_len"], cfg["pols"], cfg["eta"]
    need_dense = _matrices_per_partition(pols, eta) * 16.0 * npart**2 * workers
    dense_ok = npart <= MAX_UNKNOWNS and need_dense <= budget
    block = _fast_block_wl(height, eta)
    fast_fit = 3.0 * block <= part_len
    need_fast = math.inf
    if fast_fit and npart <= MAX_FAST_UNKNOWNS:
        try:
            need_fast = _fast_bytes(npart, dx, height, part_len, eta) * workers
        except FastSolverUnsuitable:
            fast_fit = False
    fast_ok = fast_fit and need_fast <= budget
    hint = (" or a smoother surface (smaller rms_height_wl / corr_length_wl)" if why else " or a lower pts_per_wl")
    if cfg["solver"] == "dense" or (cfg["solver"] == "auto" and not fast_ok):
        if npart > MAX_UNKNOWNS:
            raise UsageError(f"pts_per_wl={cfg['pts_per_wl']:g}{why} needs {npart} unknowns per partition of "
                             f"{part_len:g} wavelengths, more than {MAX_UNKNOWNS} (a dense solve of that size takes "
                             "many CPU minutes per partition)"
                             + ("" if cfg["solver"] == "dense" else
                                f", and the fast solver cannot take it (height range {height:.3g} wavelengths needs "
                                f"blocks of {block:.3g}; at most a third of the partition)")
                             + ": use shorter partitions (more `partitions`)" + hint)
        if need_dense > budget:
            raise UsageError(f"pts_per_wl={cfg['pts_per_wl']:g}{why} needs {npart} unknowns per partition of "
                             f"{part_len:g} wavelengths, {resources.format_bytes(need_dense)} for {workers} worker(s), more "
                             f"than the {resources.format_bytes(budget)} available: use shorter partitions (more "
                             "`partitions`)" + hint)
        return "dense", dense_ok
    if cfg["solver"] == "fast" and not fast_ok:
        if not fast_fit and dense_ok:
            return "fast", dense_ok      # solve_partition falls back to dense, with a warning naming why
        raise UsageError(f"solver='fast' cannot take partitions of {part_len:g} wavelengths with {npart} unknowns"
                         f"{why}: " + (f"the height range {height:.3g} wavelengths needs blocks of {block:.3g}, more "
                                       "than a third of the partition" if not fast_fit else
                                       f"more than {MAX_FAST_UNKNOWNS} unknowns" if npart > MAX_FAST_UNKNOWNS else
                                       f"{resources.format_bytes(need_fast)} for {workers} worker(s), more than the "
                                       f"{resources.format_bytes(budget)} available")
                         + "; use shorter partitions (more `partitions`)" + hint)
    if cfg["solver"] == "auto" and npart < AUTO_FAST_UNKNOWNS and dense_ok:
        return "dense", dense_ok
    return "fast", dense_ok


def _check_surface_memory(points: int) -> None:
    """The surface itself, before it is drawn: a long surface alone can exceed the memory."""
    per_point = resources.COSTS.surface_bytes_per_point
    resources.check_memory(per_point * points, f"the MoM surface ({points} points, {per_point} B each)",
                           "use a shorter length_wl or a lower pts_per_wl", fraction=0.8)


def _realise_surface(cfg, workers):
    """Stage 2: the surface realisation, resampled along its arc length where steep; the method; the
    set-up's failure reasons (sampling, taper, partition, interior wavelength)."""
    length_wl, partitions, part_len = cfg["length_wl"], cfg["partitions"], cfg["part_len"]
    pts_per_wl, corr_length_wl, rough, eta = cfg["pts_per_wl"], cfg["corr_length_wl"], cfg["rough"], cfg["eta"]
    n_part = cfg["n_part"]
    reasons = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MoMAccuracyWarning)  # re-issued by scatter
        reasons += check_sampling(n_part / part_len, corr_length_wl, rough)

    def surface(npart):
        _check_surface_memory(npart * partitions)
        try:
            return gaussian_surface(length_wl, npart * partitions, cfg["rms_height_wl"], corr_length_wl, cfg["seed"],
                                    second_derivative=True)
        except ValueError as exc:
            raise UsageError(f"pts_per_wl={pts_per_wl:g} is too coarse for corr_length_wl={corr_length_wl:g} "
                             f"(the surface spectrum needs > {3.9 / corr_length_wl:.3g} points per wavelength): "
                             f"{exc}") from None

    def height_range(f, npart):
        return float(np.max(np.ptp(f.reshape(partitions, npart), axis=1)))

    budget = 0.8 * _memory_available()
    # a first bound before any allocation: the dense path's size (or the fast path's for long partitions)
    if n_part > MAX_FAST_UNKNOWNS or (cfg["solver"] == "dense" and n_part > MAX_UNKNOWNS):
        _choose_solver(cfg, n_part, part_len / n_part, 0.0, workers, budget, "")
    x_all, f_all, s_all, c_all = surface(n_part)
    dx = part_len / n_part
    method, dense_ok = _choose_solver(cfg, n_part, dx, height_range(f_all, n_part), workers, budget, "")
    if rough:
        # the realised surface: arc length per sample and turn per cell at its steepest point
        stretch = float(np.max(np.hypot(1.0, s_all)))
        turn = float(np.max(np.abs(c_all) / (1.0 + s_all * s_all))) * dx
        refine = max(ARC_PTS_MIN * stretch * dx, turn / TURN_MAX)
        if refine > 1.0:
            new = int(math.ceil(n_part * refine * 1.02))
            method, dense_ok = _choose_solver(
                cfg, new, part_len / new, height_range(f_all, n_part), workers, budget,
                f" on this surface (steepest slope {math.sqrt(stretch**2 - 1):.3g}, "
                f"{1.0 / (dx * stretch):.2g} points per wavelength of arc length there; "
                f"resampling to >= {ARC_PTS_MIN:g})")
            n_part = new
            dx = part_len / n_part
            x_all, f_all, s_all, c_all = surface(n_part)
    if eta is not None:
        reasons += _check_interior(eta, dx, s_all, pts_per_wl)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MoMAccuracyWarning)
        reasons += check_taper(cfg["theta_i"], cfg["w"], part_len, cfg["pols"], cfg.get("beam"), eta)
        reasons += check_partition(part_len, corr_length_wl, rough)
    return dict(x=x_all, f=f_all, s=s_all, c=c_all, n_part=n_part, dx=dx, method=method, dense_ok=dense_ok,
                reasons=reasons, fine=power_grid(cfg["w"]))


def _check_interior(eta, dx, slope, pts_per_wl):
    """A finite index: the interior wavelength's sampling (refused below 2 points, a reason below 5) and the skin
    depth's quadrature panels per cell (refused above MAX_PANELS); returns the reasons."""
    reasons = []
    n_in = max(1.0, eta.real)
    ppw_in = 1.0 / (dx * n_in)
    if ppw_in < 2.0:
        raise UsageError(f"pts_per_wl={pts_per_wl:g} gives {ppw_in:.2g} points per interior wavelength "
                         f"(lambda / n, n={eta.real:g}): must be >= 2; raise pts_per_wl")
    if ppw_in < 5.0:
        reasons.append(f"only {ppw_in:.2g} points per interior wavelength (lambda / n, n={eta.real:g}): "
                       "the field inside the material is not resolved")
    panels = math.ceil(-eta.imag * K0 * dx * float(np.max(np.hypot(1.0, slope))))
    if panels > MAX_PANELS:
        raise UsageError(f"k={-eta.imag:g} gives a skin depth of {1 / (-eta.imag * K0):.2g} wavelengths, "
                         f"{panels} quadrature panels per cell (> {MAX_PANELS}): use k <= "
                         f"{MAX_PANELS / (K0 * dx):.3g} at this sampling, or the PEC (n=None)")
    return reasons


def _partition_tasks(cfg, surf):
    """The partitions as independent tasks, in local coordinates centred on each partition (the incident
    phase is referred to x_m, so the partition average of F is the coherent field)."""
    n_part, part_len = surf["n_part"], cfg["part_len"]
    tasks = []
    for m in range(cfg["partitions"]):
        sl = slice(m * n_part, (m + 1) * n_part)
        tasks.append({"x": surf["x"][sl] - (m + 0.5) * part_len, "y": surf["f"][sl].copy(),
                      "dfdx": surf["s"][sl].copy(), "d2fdx2": surf["c"][sl].copy(), "dx": surf["dx"],
                      "theta_i": cfg["theta_i"], "theta_r": cfg["theta_r"], "theta_fine": surf["fine"],
                      "w": cfg["w"], "pols": cfg["pols"], "eta": cfg["eta"], "solver": surf["method"],
                      "tol": cfg["tol"], "dense_ok": surf["dense_ok"], "beam": cfg.get("beam")})
    return tasks


def _solve_partitions(tasks, executor, workers, cfg, progress):
    """Stage 3: every partition solved and radiated (solve_partition) on the executor."""
    own = executor is None
    ex = process_pool(workers) if own else executor
    update = _progress_reporter(cfg["partitions"], progress)
    results = None
    try:
        # never a blind wait: liveness checks, the caller's timeout and a heartbeat (gather.py) through the
        # progress callback (None: stderr lines, as True; False: none)
        results = gather(ex, solve_partition, tasks, timeout=cfg["timeout"], on_done=update,
                         heartbeat=as_callback(True if progress is None else progress, prefix=""),
                         what="partition", label="mom.scatter")
        return results
    finally:
        if own:          # after a failure, no wait for a running partition: its worker is ended
            end_pool(ex, finished=results is not None)


def _solver_reasons(results):
    """The fast solver's fallbacks over all partitions, one line per kind of fallback with a count."""
    seen = {}
    for i, r in enumerate(results):
        for msg in r.get("reasons", ()):
            key = msg.split(" (")[0]
            seen.setdefault(key, []).append((i, msg))
    return [f"{len(v)} of {len(results)} partitions: {v[0][1]} (first: partition {v[0][0]})" for v in seen.values()]


def _mean_se(stack, M):
    """Partition mean and its standard error (spread between partitions)."""
    mean = stack.mean(axis=0)
    se = stack.std(axis=0, ddof=1) / math.sqrt(M) if M > 1 else np.zeros_like(mean)
    return mean, se


def _coherent(F, P, M, norm):
    """|<F>|^2 without the 1/M bias of |mean F|^2: (M |mean F|^2 - mean |F|^2) / (M - 1)."""
    if M == 1:
        return norm * np.abs(F[0]) ** 2
    return norm * (np.abs(F.mean(axis=0)) ** 2 * M - P.mean(axis=0)) / (M - 1)


def _statistics(results, cfg, surf):
    """Stage 4: Eq. 23's partition average, standard errors, coherent part, power balance, Mueller elements."""
    M, w, pols, theta_i, fine = cfg["partitions"], cfg["w"], cfg["pols"], cfg["theta_i"], surf["fine"]
    # Eq. 23 with F = -j k0 (Eq. 21's sum): sigma = |F|^2 / (8 pi w sqrt(pi/2)), partition mean
    # (w sqrt(pi/2) for a windowed current; a beam's power over cos ti: beam.gaussian_beam)
    length = results[0].get("length", np.full(np.size(theta_i), w * math.sqrt(math.pi / 2.0)))
    norm = 1.0 / (8.0 * math.pi * length)[:, None]
    sum_flux = sum(r["flux"] for r in results)
    cos_i = np.cos(theta_i)
    nominal_flux = M * length * cos_i
    per = {}
    for pol in pols:
        F = np.stack([r["F_" + pol] for r in results])
        Ff = np.stack([r["Ffine_" + pol] for r in results])
        P = np.abs(F) ** 2
        Pf = np.abs(Ff) ** 2
        sig, se = _mean_se(norm * P, M)
        fine_sig = norm * Pf.mean(axis=0)
        nominal = np.trapezoid(fine_sig, fine, axis=1) / (2.0 * math.pi * cos_i)
        power = nominal * nominal_flux / sum_flux
        absorbed = sum(r["absorbed_" + pol] for r in results) / sum_flux
        per[pol] = dict(F=F, scaled=F * np.sqrt(norm), sigma=sig, se=se, fine=fine_sig, nominal=nominal, power=power,
                        absorbed=absorbed,
                        energy=power + absorbed, coherent=_coherent(F, P, M, norm),
                        power_coherent=np.trapezoid(_coherent(Ff, Pf, M, norm), fine, axis=1) / (2.0 * math.pi * cos_i))
    for name, d in per.items():
        for key in ("sigma", "power", "absorbed"):
            if not np.all(np.isfinite(d[key])):
                raise FloatingPointError("MoM produced non-finite values (singular moment matrix?)")
    out = dict(per=per, mueller=None, mueller_se=None, mueller_n=None, mueller_n_se=None, sigma_sp=None)
    if len(pols) == 2:
        out.update(_mueller_stats(per["s"]["F"], per["p"]["F"], norm, M))
    return out


def _mueller_stats(Fs, Fp, norm, M):
    """The in-plane Mueller elements of the partitions' far fields: means, standard errors, ratios to M00 (of the
    partition sums, jackknife standard errors) and the cross term sigma_sp."""
    X = norm * Fs * np.conj(Fp)
    Ps, Pp = norm * np.abs(Fs) ** 2, norm * np.abs(Fp) ** 2
    stacks = {"M00": 0.5 * (Ps + Pp), "M01": 0.5 * (Ps - Pp), "M22": X.real, "M23": X.imag}
    mueller, mueller_se = {}, {}
    for key, st in stacks.items():
        mueller[key], mueller_se[key] = _mean_se(st, M)
    mueller_n, mueller_n_se = {}, {}
    den_sum = stacks["M00"].sum(axis=0)
    for key in ("M01", "M22", "M23"):
        num_sum = stacks[key].sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):  # M00 = 0 only where nothing is scattered
            ratio = num_sum / den_sum
            if M > 1:  # jackknife over partitions
                jack = (num_sum - stacks[key]) / (den_sum - stacks["M00"])
                se = np.sqrt((M - 1) / M * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0))
            else:
                se = np.zeros_like(ratio)
        mueller_n[key + "/M00"], mueller_n_se[key + "/M00"] = ratio, se
    return dict(mueller=mueller, mueller_se=mueller_se, mueller_n=mueller_n, mueller_n_se=mueller_n_se,
                sigma_sp=X.mean(axis=0))


def _energy_check(per, cfg):
    """Stage 5: the energy check after every solve -- a result that does not conserve energy is never quiet."""
    post = []
    for pol, d in per.items():
        bad = np.abs(d["energy"] - 1.0) > ENERGY_TOLERANCE
        if np.any(bad):
            vals = ", ".join(f"{e:.4g} at {t:g} deg" for e, t in zip(d["energy"][bad], cfg["ti_deg"][bad]))
            post.append(f"{pol}-pol reflected + absorbed power is {vals} (should be 1 within {ENERGY_TOLERANCE:g}): "
                        "the solution does not conserve energy; refine pts_per_wl or widen the taper")
    return post


def _result(cfg, surf, results, stats, reasons, wall):
    """The MoMResult of the stages' outputs."""
    per, pols, eta, dx = stats["per"], cfg["pols"], cfg["eta"], surf["dx"]
    first = per[pols[0]]
    times = sum(r["times"] for r in results)
    used = sorted({r.get("solver", "dense") for r in results})
    residuals = [r["residual"] for r in results if r.get("residual") is not None]
    get = lambda pol, key: per[pol][key] if pol in per else None  # noqa: E731
    return MoMResult(
        theta_i=cfg["theta_i"], theta_r=cfg["theta_r"], sigma=first["sigma"], sigma_coherent=first["coherent"],
        sigma_incoherent=first["sigma"] - first["coherent"], power_balance=first["power"],
        power_balance_nominal=first["nominal"], power_coherent=first["power_coherent"],
        fine_theta_r=surf["fine"], fine_sigma=first["fine"], sigma_std_error=first["se"],
        times={"fill": times[0], "factor": times[1], "solve": times[2], "far_field": times[3], "wall": wall},
        params={"length_wl": cfg["length_wl"], "partitions": cfg["partitions"], "partition_length_wl": cfg["part_len"],
                "unknowns_per_partition": surf["n_part"], "dx_wl": dx, "pts_per_wl": 1.0 / dx,
                "pts_per_wl_requested": cfg["pts_per_wl"],
                "taper_width_wl": cfg["w"], "rms_height_wl": cfg["rms_height_wl"],
                "corr_length_wl": cfg["corr_length_wl"],
                "rms_slope": math.sqrt(2.0) * cfg["rms_height_wl"] / cfg["corr_length_wl"], "seed": cfg["seed"],
                "polarization": pols, "n": None if eta is None else eta.real,
                "k": None if eta is None else -eta.imag,
                "solver": used[0] if len(used) == 1 else "+".join(used), "solver_requested": cfg["solver"],
                "tol": cfg["tol"] or FAST_TOL,
                "incidence": ["beam" if b else "window" for b in cfg["beam"]],
                "max_residual": max(residuals) if residuals else None},
        warnings=reasons, polarization=pols,
        sigma_s=get("s", "sigma"), sigma_p=get("p", "sigma"), sigma_sp=stats["sigma_sp"],
        sigma_s_std_error=get("s", "se"), sigma_p_std_error=get("p", "se"),
        fine_sigma_s=get("s", "fine"), fine_sigma_p=get("p", "fine"),
        power_balance_s=get("s", "power"), power_balance_p=get("p", "power"),
        absorbed_s=get("s", "absorbed"), absorbed_p=get("p", "absorbed"),
        energy_s=get("s", "energy"), energy_p=get("p", "energy"),
        mueller=stats["mueller"], mueller_std_error=stats["mueller_se"],
        mueller_normalised=stats["mueller_n"], mueller_normalised_std_error=stats["mueller_n_se"],
        partition_fields={pol: per[pol]["scaled"] for pol in pols},
        **_floors(cfg, per),
    )


def _floors(cfg, per):
    """Stage 6: the floor of each polarisation's sigma and where sigma stands clear of it (MoMResult fields)."""
    out = {}
    for pol in ("s", "p"):
        if pol not in per:
            out[f"floor_{pol}"] = out[f"valid_{pol}"] = None
            continue
        fl = partition_floor(cfg["theta_i"], cfg["theta_r"], cfg["w"], cfg["part_len"], cfg["beam"], pol,
                             cfg["tol"] or FAST_TOL, sigma_h=cfg["rms_height_wl"])
        out[f"floor_{pol}"], out[f"valid_{pol}"] = fl, per[pol]["sigma"] >= FLOOR_MARGIN * fl
    out["valid"] = out[f"valid_{cfg['pols'][0]}"]
    out["floor_reason"] = floor_reason(cfg["w"], cfg["part_len"])
    return out
