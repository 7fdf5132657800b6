"""Fast MoM solver for long, near-planar partitions: forward-backward sweeps with spectral acceleration.

What it solves
--------------
The same discretised equations as the dense path (:mod:`hyde_bsdf.mom.dense`; operators of
:mod:`hyde_bsdf.mom.kernels`): for a PEC the EFIE ``S0 v = psi`` (s) or the MFIE
``(1/2 - D0) u = psi`` (p); for a finite index the coupled two-region system

    (1/2 - D0) u + S0 v = psi,        (1/2 + D1) u - rho S1 v = 0,

in u and v together (the dense path eliminates u; the answer is the same).  Nothing of
size N x N is formed.

How (Holliday, DeRaad & St-Cyr, IEEE TAP 44, 722 (1996); Kapp & Brown, IEEE TAP 44, 711
(1996); Chou & Johnson, Radio Sci. 33, 1277 (1998))
-------------------------------------------------------------------------------------
The partition is cut into blocks of ``B`` samples (at least ``near_wl`` wavelengths).

* **Strong (near) part**: every entry of the dense matrix whose column lies in the row's
  block or a neighbouring block, filled with the dense path's formulas (near cells by
  Gauss-Legendre over the osculating parabola, far cells by the phase moments), stored
  as a block-tridiagonal matrix: O(N B) numbers.
* **Weak (far) part**, columns two or more blocks away: the spectral (plane-wave)
  representation of the Green's function (Sommerfeld; Chou & Johnson's "spectral
  acceleration"), for x > x'

      -(j/4) H0^(2)(k R) = -(j / 4 pi) int_C exp(-j k ((x - x') cos phi + (y - y') sin phi)) d phi,

  on the contour phi = s (1 + j), s in [-pi/2, pi/2] (through the saddle point of a
  near-grazing path, decaying at both ends), with a trapezoid rule in a stretched
  variable (fine near s = 0 where the long-range interactions live, coarse elsewhere;
  :func:`spectral_rule`) checked against the Hankel function on the partition's range
  of distances and heights before it is used.  The samples are uniform in x, so a plane
  wave's x-dependence within a block is one table; the factors are formed in cache-sized
  row chunks, complex exponentials in real arithmetic.  Each source cell is integrated exactly
  per plane wave against the quadratic interpolant of the samples (the dense path's
  cell moments), the double layer carries j k (sin phi - f' cos phi).  A block's
  sources are summed into Q plane-wave amplitudes, propagated block to block by
  exp(-j k L cos phi) and evaluated at the receivers: O(N Q) per product, in both
  directions (the backward one on the mirrored surface).
* **Forward-backward iteration**: a block symmetric Gauss-Seidel sweep (forward
  through the blocks with the updated values behind and the previous ones ahead, then
  backward), the method of moments' "forward-backward method" (FBM), all incidence
  angles at once.  Each directional sweep accumulates its own far part on the way (for the
  final values: every block's far sources are two or more blocks behind), which is the other
  direction's "ahead" part: no extra product.  The true residual ||b - A x|| / ||b|| (one
  product of the strong part and one far direction) is computed after the first two sweeps and
  wherever the estimate from the step size (linear convergence: the residual falls as the step)
  says converged, rising or stalling; below ``tol`` it stops.
* **Guards**: a sweep that raises the residual (a steep or re-entrant realisation,
  multiple scattering that the sweep order cannot follow: Infragold V-grooves with flanks of
  slope 6 diverge in p at sweep 2, ``tests/test_mom_fast.py``) or stalls (less than 10 %
  gain per sweep over three sweeps), or ``max_sweeps`` reached, hands the best iterate
  to restarted GMRES preconditioned by the sparse LU of the strong part (the same fast
  product); if GMRES does not reach ``tol`` either, the caller falls back to the
  dense LU only where it fits and costs at most 10x the fast solve (:mod:`hyde_bsdf.mom.solver`),
  and every step says why in ``info["reasons"]``.

Limits: the plane-wave sum needs k H^2 / (4 L_s) <= 25 (H the partition's height
range, L_s the block length); the blocks are sized for e^16 (``BLOCK_GROWTH``: rounding
1e-16 e^16 stays far below the rule's 1e-7), lengthened (growth x 0.75, three times) where
a rule still misses its tolerance, so a very rough surface gets long blocks, and when the
block would exceed a third of the partition the fast solver declines
(:class:`FastSolverUnsuitable`).  A lossy interior (a metal) is banded and needs no far
part; a lossless or weakly lossy one (glass) gets its own spectral far part with
k1 = k0 eta, on the contour turned by -arg(k1)/2 (the steepest-descent line of a lossy
saddle); a rule whose plane waves would grow along x is refused, and one that does not reach
its tolerance over the first blocks (eta = 0.5 - 0.3j on a surface with a 4.8-lambda height
range stalled at 0.015 over 3-lambda blocks: the turned line's truncation) gets longer blocks
(4.1 lambda there) -- before, such partitions went to the dense LU.
"""
from __future__ import annotations

import math
import time

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.mom.kernels import (
    DECAY_CUTOFF, K0, _cell_moments, _complex_weights, _interp_weights, _near, _self, _sinc_derivatives, hankel2,
)

__all__ = ["solve_fast", "spectral_rule", "block_length_wl", "plan_blocks", "FastSolverUnsuitable", "FAST_TOL",
           "NEAR_WL"]

#: default relative residual ||b - A x|| / ||b|| at which the iteration stops
FAST_TOL = 1e-4
#: shortest block (strong-interaction length) in wavelengths
NEAR_WL = 3.0
#: largest exp(k H^2 / (4 L_s)) growth of the plane-wave sum allowed (digits lost: GROWTH / ln 10)
GROWTH_MAX = 25.0
#: growth k H^2 / (4 L_s) the blocks are sized for: e^16 leaves the rule 1e-16 e^16 ~ 1e-9 of rounding, well
#: below its 1e-7 tolerance (at 0.8 GROWTH_MAX = 20 the rounding, ~5e-8, met the tolerance: glass with an 11-lambda
#: height range needed 2665 plane waves or found no rule at all, and the partition went to a dense LU)
BLOCK_GROWTH = 16.0
#: sweeps of the forward-backward iteration before GMRES takes over
MAX_SWEEPS = 30
_NEAR = 4  # near-cell offsets integrated by Gauss-Legendre (as kernels.layer_matrices)


class FastSolverUnsuitable(ValueError):
    """The surface is too rough (height range against partition length) for the spectral far part."""


class _RuleShort(FastSolverUnsuitable):
    """No plane-wave rule reached its tolerance (rounding in the growing sum): longer blocks may do."""


# ---------------------------------------------------------------------------
# The plane-wave (spectral) representation of the Green's function
# ---------------------------------------------------------------------------

def _rule_nodes(h0, h_far, hu=0.1, tilt=0.0):
    """Nodes phi = s (1 + j) e^{j tilt} and weights of d phi, s = s1 asinh((c / s1) sinh u) on a uniform u grid.

    Step in s about h0 near s = 0, h_far for |s| >> h_far / hu (analytic map: the trapezoid
    rule keeps its exponential convergence); |Re phi| <= pi/2.  ``tilt`` turns the line
    through the saddle by -arg(k)/2 for a lossy k (the steepest-descent direction).
    """
    direction = (1 + 1j) if tilt == 0.0 else math.sqrt(2.0) * complex(math.cos(math.pi / 4 + tilt),
                                                                        math.sin(math.pi / 4 + tilt))
    s_end = 0.5 * math.pi / direction.real
    c, s1 = h0 / hu, h_far / hu
    U = math.asinh((s1 / c) * math.sinh(s_end / s1)) if s_end / s1 < 700 else 700.0
    n = int(math.ceil(U / hu))
    u = np.linspace(-U, U, 2 * n + 1)
    du = u[1] - u[0]
    sh = np.sinh(u)
    s = s1 * np.arcsinh((c / s1) * sh)
    with np.errstate(over="ignore"):
        ds = c * np.cosh(u) / np.sqrt(1.0 + ((c / s1) * sh) ** 2)
    keep = np.abs(s) <= s_end
    return (s[keep] * direction), (ds[keep] * du * direction)


def _rule_error(phi, w, k, near_wl, length_wl, height_wl):
    """Largest error of the rule for -(j/4) H0(k R), R over the partition's far pairs, relative to the
    lossless amplitude (1/4) sqrt(2 / (pi |k| dx))."""
    dxs = np.geomspace(near_wl, max(length_wl, near_wl * 1.01), 16)[:, None]
    dys = np.linspace(-height_wl, height_wl, 9)[None, :]
    exact = -0.25j * hankel2(0, k * np.hypot(dxs, dys))
    ph = np.exp(-1j * k * (dxs[..., None] * np.cos(phi) + dys[..., None] * np.sin(phi)))
    approx = (-0.25j / math.pi) * (ph @ w)
    scale = 0.25 * np.sqrt(2.0 / (math.pi * abs(k) * dxs))
    return float(np.max(np.abs(approx - exact) / scale))


def spectral_rule(k, near_wl, length_wl, height_wl, tol=1e-7):
    """Quadrature nodes phi_q and weights w_q with -(j/4) H0(k R) ~ -(j/(4 pi)) sum_q w_q e^{-jk(dx cos phi_q + dy sin phi_q)}.

    Valid for near_wl <= dx <= length_wl and |dy| <= height_wl (checked on a grid of such
    pairs to ``tol``, refined until it holds).  Raises FastSolverUnsuitable when the sum's
    growth k H^2 / (4 L_s) exceeds GROWTH_MAX or no rule reaches ``tol``.
    """
    kk = abs(complex(k))
    growth = kk * height_wl ** 2 / (4.0 * near_wl)
    if growth > GROWTH_MAX:
        raise FastSolverUnsuitable(
            f"height range {height_wl:.3g} wavelengths over blocks of {near_wl:.3g}: the plane-wave sum would "
            f"grow by e^{growth:.0f} (limit e^{GROWTH_MAX:g})")
    h0 = 0.6 / math.sqrt(kk * max(length_wl, near_wl))
    h_far = min(0.09, 1.5 / (kk * max(height_wl, 0.5)))     # coarse first; refined below until the check holds
    h0 = min(h0, h_far)
    tilt = max(0.0, -0.5 * math.atan2(complex(k).imag, complex(k).real))   # a lossy k turns the saddle
    err = math.inf
    for _ in range(10):
        phi, w = _rule_nodes(h0, h_far, tilt=tilt)
        if np.any((-1j * k * np.cos(phi)).real > 1e-12):
            raise FastSolverUnsuitable(f"the plane waves of k={k} grow along x on the contour (tilt "
                                       f"{math.degrees(tilt):.1f} deg)")
        err = _rule_error(phi, w, k, near_wl, length_wl, height_wl)
        if err <= tol:
            return phi, w
        h0 *= 0.7
        h_far *= 0.7
    raise _RuleShort(f"no plane-wave rule reached the tolerance {tol:.3g} (the best, {err:.3g}, is above it) for "
                     f"k={k:.4g}, blocks of {near_wl:.3g}, length {length_wl:.3g}, height range {height_wl:.3g}")


# ---------------------------------------------------------------------------
# Blocks
# ---------------------------------------------------------------------------

class _Blocks:
    """Block bounds of a partition of n samples (blocks of b, the last one possibly shorter)."""

    def __init__(self, n, b):
        self.n, self.b = n, b
        self.bounds = np.append(np.arange(0, n, b), n)
        if self.bounds.size > 2 and self.bounds[-1] - self.bounds[-2] < b // 2:
            self.bounds = np.delete(self.bounds, -2)  # fold a stub into the previous block
        self.nb = self.bounds.size - 1
        self.of = np.repeat(np.arange(self.nb), np.diff(self.bounds))   # block of each sample
        self.width = int(np.max(np.diff(self.bounds)))


# ---------------------------------------------------------------------------
# The strong part: the dense matrix's entries in the block band
# ---------------------------------------------------------------------------

class _BandStore:
    """Adapter: M[m, s] on diagonal storage (lets kernels._near/_self write into a band)."""

    def __init__(self, data, half):
        self.data, self.half = data, half
        self.shape = (data.shape[0], data.shape[0])

    def __getitem__(self, idx):
        m, s = idx
        return self.data[m, s - m + self.half]

    def __setitem__(self, idx, val):
        m, s = idx
        self.data[m, s - m + self.half] = val


class _FarCells:
    """The dense path's far-cell weights of one region (kernels.layer_matrices' formulas): cells more than
    4 samples from the match point and, in a lossy medium, within the e^-40 cut-off ``band``."""

    def __init__(self, x, y, fp, dx, k, band, need_S, need_D):
        self.x, self.y, self.fp, self.dx, self.k, self.band = x, y, fp, dx, k, band
        self.decay = abs(complex(k).imag)
        self.need_S, self.need_D = need_S, need_D

    def weights(self, m, cell):
        """(ws, wd): far-cell weights (w0, w+, w-) for match points m [..., rows, 1], cells [..., 1, cols]
        (None where not asked): lossless, the phase moments with the asymptotic amplitude slope; lossy,
        the exact log-derivative."""
        x, y, fp, dx, k = self.x, self.y, self.fp, self.dx, self.k
        sep = np.abs(cell - m)
        inside = (sep > _NEAR) & (sep <= self.band)
        ddx = x[cell] - x[m]
        ddy = y[cell] - y[m]
        R = np.where(inside, np.hypot(ddx, ddy), 1.0)  # guard: near/self cells are integrated apart
        fpc = fp[cell]
        kr = k * R
        ws = wd = None
        if self.decay == 0.0:
            drdt = (ddx + ddy * fpc) / R
            sd = _sinc_derivatives((0.5 * k * dx) * drdt)
            eps = (-0.5 * dx) * drdt / R
            if self.need_S:
                ws = _interp_weights(np.where(inside, (-0.25j * dx) * hankel2(0, kr), 0.0), sd, eps)
            if self.need_D:
                K = np.where(inside, (0.25j * k * dx) * hankel2(1, kr) * (-fpc * ddx + ddy) / R, 0.0)
                wd = _interp_weights(K, sd, 3.0 * eps)
        else:
            drdt = (0.5j * dx) * (ddx + ddy * fpc) / R
            h0 = hankel2(0, kr)
            h1 = hankel2(1, kr)
            if self.need_S:
                ws = _complex_weights(np.where(inside, (-0.25j * dx) * h0, 0.0),
                                      _cell_moments(drdt * (-k) * h1 / h0))
            if self.need_D:
                K = np.where(inside, (0.25j * k * dx) * h1 * (-fpc * ddx + ddy) / R, 0.0)
                wd = _complex_weights(K, _cell_moments(drdt * (k * h0 / h1 - 2.0 / R)))
        return ws, wd


def _spread(wts):
    """Rectangle over columns c0 - 1 .. c1: v_{n+1} weights one to the right, v_{n-1} one to the left."""
    w0, wp, wm = wts
    rect = np.zeros(w0.shape[:-1] + (w0.shape[-1] + 2,), complex)
    rect[..., 1:-1] += w0
    rect[..., 2:] += wp
    rect[..., :-2] += wm
    return rect


def _fill_regular_blocks(cells, mats, bounds, half, reg, bsz):
    """Far-cell entries of the blocks ``reg`` (away from the partition ends, neighbours of ``bsz`` samples too)
    all at once: the geometry of the rectangle in index offsets is the same for every one of them."""
    i = np.arange(bsz)
    t = np.arange(3 * bsz)
    bcol = (t[None, :] - bsz - i[:, None] + half)[None]                      # [1, b, 3b]
    per = max(1, 65536 // (bsz * (3 * bsz + 2)))                             # blocks at a time (cache-sized)
    for g0 in range(0, reg.size, per):
        grp = reg[g0:g0 + per]
        m = bounds[grp][:, None, None] + i[None, :, None]                     # [nr, b, 1]
        cell = (bounds[grp - 1] - 1)[:, None, None] + np.arange(3 * bsz + 2)[None, None, :]
        for M, wts in zip(mats, cells.weights(m, cell)):
            if M is not None:
                M[m, bcol] = _spread(wts)[:, :, 2:2 + 3 * bsz]


def _fill_block(cells, mats, bounds, half, j):
    """Far-cell entries of block j's rows over the columns of blocks j-1 .. j+1, the weights of the cells
    beyond the partition ends folded into the end cell's column."""
    n, nb = cells.x.size, bounds.size - 1
    a, b = bounds[j], bounds[j + 1]
    lo, hi = bounds[max(j - 1, 0)], bounds[min(j + 2, nb)]      # the columns kept
    c0, c1 = max(lo - 1, 0), min(hi + 1, n)                     # cells that reach them
    m = np.arange(a, b)[:, None]
    for M, wts in zip(mats, cells.weights(m, np.arange(c0, c1)[None, :])):
        if M is None:
            continue
        rect = _spread(wts)
        if c1 == n:                      # partition ends: folded into the end cell's column
            rect[:, -2] += rect[:, -1]
        if c0 == 0:
            rect[:, 1] += rect[:, 0]
        cols = np.arange(lo, hi)
        M[a:b][np.arange(b - a)[:, None], cols[None, :] - m + half] = rect[:, cols - c0 + 1]


def _band_fill(x, y, fp, fpp, dx, k, bounds, half, need_S, need_D):
    """Entries M[m, c] of the single/double layer matrices of kernels.layer_matrices for the columns c in
    the row's block and its two neighbours, on diagonal storage [N, 2 half + 1] (M[m, c] at c - m + half).

    Same formulas: far cells (|m - cell| > 4) by the phase moments (lossless: the asymptotic
    amplitude slope; lossy: the exact log-derivative and the e^-40 cut-off), near and self
    cells by kernels._near/_self, the quadratic interpolant's weights spread to the
    neighbouring columns and folded at the partition ends.  Returns (S, D, band) (None where
    not asked; band = the lossy cut-off in cells).
    """
    n = x.size
    k = complex(k) if complex(k).imag else float(np.real(k))
    decay = abs(complex(k).imag)
    band = min(n - 1, int(math.ceil(DECAY_CUTOFF / (decay * dx)))) if decay > 0 else n - 1
    width = 2 * half + 1
    S = np.zeros((n, width), complex) if need_S else None
    D = np.zeros((n, width), complex) if need_D else None
    cells = _FarCells(x, y, fp, dx, k, band, need_S, need_D)
    nb = bounds.size - 1
    lens = np.diff(bounds)
    bsz = int(lens[0])
    # blocks away from the partition ends whose neighbours have bsz samples too: all at once
    reg = np.array([j for j in range(2, nb - 2) if lens[j - 1] == lens[j] == lens[j + 1] == bsz], dtype=int)
    if reg.size:
        _fill_regular_blocks(cells, (S, D), bounds, half, reg, bsz)
    done = set(reg.tolist())
    for j in range(nb):
        if j not in done:
            _fill_block(cells, (S, D), bounds, half, j)
    offsets = [o for o in range(-_NEAR, _NEAR + 1) if o != 0 and abs(o) < n]
    SA = _BandStore(S, half) if need_S else None
    DA = _BandStore(D, half) if need_D else None
    _near(x, y, fp, fpp, dx, k, offsets, need_S, need_D, SA, DA)
    _self(x, y, fp, fpp, dx, k, need_S, need_D, SA, DA)
    return S, D, band


# ---------------------------------------------------------------------------
# The weak part: plane-wave sums block to block
# ---------------------------------------------------------------------------

def _exp_pair(z):
    """exp(z) and exp(-z) for complex z from one real exp, cos and sin (NumPy's complex exp is ~3x slower)."""
    mag = np.exp(z.real)
    c, sn = np.cos(z.imag), np.sin(z.imag)
    e = np.empty(z.shape, complex)
    np.multiply(mag, c, out=e.real)
    np.multiply(mag, sn, out=e.imag)
    np.divide(1.0, mag, out=mag)
    ei = np.empty(z.shape, complex)
    np.multiply(mag, c, out=ei.real)
    np.multiply(mag, sn, out=ei.imag)
    np.negative(ei.imag, out=ei.imag)
    return e, ei


def _cell_weights(a, e, ei, dx):
    """Weights of v_n, v_{n+1}, v_{n-1} of a cell (kernels._complex_weights(dx, kernels._cell_moments(a)))
    for complex a, given e = exp(j a) and ei = exp(-j a).

    With sa = sin a, m0 = sa / a, d1 = (cos a - m0) / a = sinc', d2 = -(2 d1 + sa) / a = sinc''
    (the moments m1 = (j/2) d1, m2 = -d2/4): w0 = dx (m0 - m2), w+ = dx (m1 + m2) / 2,
    w- = dx (m2 - m1) / 2; Taylor series where |a| < 0.2.
    """
    small = np.abs(a) < 0.2
    any_small = bool(np.any(small))
    ag = np.where(small, 1.0, a) if any_small else a
    inv = 1.0 / ag
    sa = e - ei
    sa *= -0.5j
    d1 = e + ei
    d1 *= 0.5
    m0 = sa * inv
    d1 -= m0
    d1 *= inv
    d2 = d1 * 2.0
    d2 += sa
    d2 *= inv
    d2 *= -1.0
    if any_small:
        b = a[small]
        b2 = b * b
        m0[small] = 1.0 - b2 / 6.0 + b2 * b2 / 120.0 - b2 ** 3 / 5040.0
        d1[small] = b * (-1.0 / 3.0 + b2 / 30.0 - b2 * b2 / 840.0)
        d2[small] = -1.0 / 3.0 + b2 / 10.0 - b2 * b2 / 168.0
    d2 *= 0.25 * dx                      # -m2 dx
    d1 *= 0.5j * dx                      # m1 dx
    w0 = m0
    w0 *= dx
    w0 += d2
    wp = d1 - d2
    wp *= 0.5
    wm = d1 + d2
    wm *= -0.5
    return w0, wp, wm


def _interp_sources(g, w0, wp, wm, bounds, prop, edge):
    """Source factors [N, Q] of one direction's frame (receivers right of their sources).

    Each column c collects the cells c - 1, c, c + 1 that its sample's quadratic interpolant
    reaches (weights wp, w0, wm of cells c - 1, c, c + 1; the partition ends folded into the end
    columns as in the dense path), each cell's plane-wave factor g referred to the right edge of
    the column's own block: a cell of the previous block is carried across the column's block
    (prop), and the first cell of the next block gets ``edge`` (its factor against the previous
    block's right edge) in place of g.
    """
    acc = w0 * g
    acc[1:] += wp[:-1] * g[:-1]       # cell c - 1's v_{n+1} weight, to column c
    acc[:-1] += wm[1:] * g[1:]        # cell c + 1's v_{n-1} weight, to column c
    acc[0] += wm[0] * g[0]            # partition ends: folded into the end cell's column
    acc[-1] += wp[-1] * g[-1]
    first = bounds[1:-1]              # first sample of blocks 1 .. nb-1
    if first.size:
        acc[first] += wp[first - 1] * g[first - 1] * (prop[1:] - 1.0)
        acc[first - 1] += wm[first] * (edge - g[first])
    return acc


def _dfac_rows(k, sphi, cphi, fp_rows, sign, name):
    """The double layer's plane-wave factor j k (sin phi - sign f' cos phi) on some rows (1 for the single layer)."""
    if name == "S":
        return 1.0
    return (1j * k) * (sphi[None, :] - sign * fp_rows[:, None] * cphi[None, :])


class _Far:
    """Far part of one region's S and D, both directions, in the natural sample order.

    Plane-wave factors for receivers right of their sources ("fwd") and left of them ("bwd":
    the mirrored surface x -> -x, f' -> -f', on which the double layer keeps its form), built
    from shared pieces: the samples are uniform in x, so the factors' x-dependence within a
    block is one table [block, Q] (exp(-j k (i + 1/2) dx cos phi)), the height factor
    exp(j k y sin phi) and the cell moments' exp(-j k dx f' sin phi / 2) are one [N, Q]
    exponential each, shared by both directions (and, in the caller, by both polarisations
    and all incidence angles).
    """

    #: rows of the plane-wave factors formed at a time (x Q complex numbers: the temporaries stay in cache)
    CHUNK_ELEMENTS = 32768

    def __init__(self, x, y, fp, dx, k, bounds, phi, w, need_S, need_D):
        self.cphi, self.sphi = np.cos(phi), np.sin(phi)
        n = x.size
        self.q = phi.size
        self.bounds = bounds
        nb = self.nb = bounds.size - 1
        lens = np.diff(bounds)
        of = np.repeat(np.arange(nb), lens)
        loc = np.arange(n) - bounds[of]
        self.y, self.fp, self.dx, self.k = y, fp, dx, k
        self.table = np.exp((-1j * k * dx) * (np.arange(int(lens.max())) + 0.5)[:, None] * self.cphi[None, :])
        self.prop = np.exp((-1j * k * dx) * lens[:, None] * self.cphi[None, :])   # across block j (either way)
        self.i_left = loc                      # table[i_left] = exp(-j k (x - left edge) cos phi)
        self.i_right = lens[of] - 1 - loc      # table[i_right] = exp(-j k (right edge - x) cos phi)
        self.half = -0.5 * k * dx              # the cell moments' a = half (cos phi +- f' sin phi)
        self.ac = self.half * self.cphi[None, :]
        self.ec, self.eci = _exp_pair(1j * self.ac)
        self.kinds = [name for name, need in (("S", need_S), ("D", need_D)) if need]
        self.rcv = {"fwd": np.empty((n, self.q), complex), "bwd": np.empty((n, self.q), complex)}
        src = {(d, name): np.empty((n, self.q), complex) for d in ("fwd", "bwd") for name in self.kinds}
        self._fill_rows(src, (-0.25j / math.pi) * w)
        self._fold_ends_and_edges(src)
        self.src = {("fwd", "S"): src.get(("fwd", "S")), ("fwd", "D"): src.get(("fwd", "D")),
                    ("bwd", "S"): src.get(("bwd", "S")), ("bwd", "D"): src.get(("bwd", "D"))}

    def _factors(self, rows):
        """Per row set: exp(+-j k y sin phi), and per (direction, kernel) the cell weights and the plane-wave
        factor G of each cell (times j k (sin phi -+ f' cos phi) for the double layer)."""
        k, fp, sphi, cphi = self.k, self.fp, self.sphi, self.cphi
        yf, yfi = _exp_pair((1j * k) * self.y[rows, None] * sphi[None, :])
        out = {}
        if self.kinds:
            af = (self.half * fp[rows])[:, None] * sphi[None, :]
            ef, efi = _exp_pair(1j * af)
            for direction, sign, idx in (("fwd", 1.0, self.i_right), ("bwd", -1.0, self.i_left)):
                # cell moments: a = -(k dx / 2)(cos phi +- f' sin phi) (fwd +, the mirrored surface -)
                if sign > 0:
                    wts = _cell_weights(self.ac + af, self.ec * ef, self.eci * efi, self.dx)
                else:
                    wts = _cell_weights(self.ac - af, self.ec * efi, self.eci * ef, self.dx)
                g = self.table[idx[rows]] * yf    # fwd: exp(j k (x - right edge) cos phi) e^{j k y sin phi}; bwd: mirrored
                for name in self.kinds:
                    if name == "S":
                        out[(direction, name)] = (wts, g)
                    else:
                        dfac = (1j * k) * (sphi[None, :] - sign * fp[rows, None] * cphi[None, :])
                        out[(direction, name)] = (wts, g * dfac)
        return yf, yfi, out

    def _fill_rows(self, src, coef):
        """Receiver factors and interior source factors (each column's cells c - 1, c, c + 1, referred to the
        column's own block edge), in row chunks of CHUNK_ELEMENTS numbers."""
        rcv, table = self.rcv, self.table
        n = self.y.size
        step = max(16, self.CHUNK_ELEMENTS // max(self.q, 1))
        for r0 in range(0, n, step):
            r1 = min(n, r0 + step)
            lo, hi = max(r0 - 1, 0), min(r1 + 1, n)          # one row either side: the interpolant's neighbours
            yf, yfi, fac = self._factors(slice(lo, hi))
            o, m = r0 - lo, r1 - r0
            yfi *= coef
            rcv["fwd"][r0:r1] = table[self.i_left[r0:r1]] * yfi[o:o + m]
            rcv["bwd"][r0:r1] = table[self.i_right[r0:r1]] * yfi[o:o + m]
            for (direction, name), ((w0, wp, wm), G) in fac.items():
                acc = src[(direction, name)][r0:r1]
                np.multiply(w0[o:o + m], G[o:o + m], out=acc)
                # fwd: column c collects cell c-1's v_{n+1} weight and cell c+1's v_{n-1} weight; the mirrored
                # direction, read in natural order, the other way round
                before, after = (wp, wm) if direction == "fwd" else (wm, wp)
                t0 = 1 if r0 == 0 else 0                    # rows with a cell c - 1
                acc[t0:] += before[o + t0 - 1:o + m - 1] * G[o + t0 - 1:o + m - 1]
                t1 = m - 1 if r1 == n else m                # rows with a cell c + 1
                acc[:t1] += after[o + 1:o + t1 + 1] * G[o + 1:o + t1 + 1]

    def _fold_ends_and_edges(self, src):
        """The partition ends (folded into the end columns) and the block edges (where the reference edge
        changes), from the factors of the few rows concerned."""
        k, fp, sphi, cphi, bounds = self.k, self.fp, self.sphi, self.cphi, self.bounds
        n = self.y.size
        first = bounds[1:-1]
        rows = np.concatenate([[0, n - 1], first - 1, first])
        yf, _, fac = self._factors(rows)
        nf = first.size
        e_last = yf[2:2 + nf] / self.table[0]           # first - 1 against block j's left edge (mirrored frame)
        e_first = yf[2 + nf:] / self.table[0]           # first against block j-1's right edge
        for (direction, name), ((w0, wp, wm), G) in fac.items():
            acc = src[(direction, name)]
            if direction == "fwd":
                acc[0] += wm[0] * G[0]
                acc[n - 1] += wp[1] * G[1]
                if nf:
                    gl, gf = G[2:2 + nf], G[2 + nf:]
                    acc[first] += wp[2:2 + nf] * gl * (self.prop[1:] - 1.0)
                    acc[first - 1] += wm[2 + nf:] * (e_first * _dfac_rows(k, sphi, cphi, fp[first], 1.0, name) - gf)
            else:
                acc[n - 1] += wm[1] * G[1]
                acc[0] += wp[0] * G[0]
                if nf:
                    gl, gf = G[2:2 + nf], G[2 + nf:]
                    acc[first - 1] += wp[2 + nf:] * gf * (self.prop[:-1] - 1.0)
                    acc[first] += wm[2:2 + nf] * (e_last * _dfac_rows(k, sphi, cphi, fp[first - 1], -1.0, name) - gl)

    def _blocked(self, arr):
        """[N, ...] -> ([nb - 1, B, ...] view of the equal blocks, the last block [L, ...])."""
        b0 = self.bounds[1]
        full = (self.nb - 1) * b0
        return arr[:full].reshape((self.nb - 1, b0) + arr.shape[1:]), arr[full:]

    def spectra(self, direction, parts):
        """[nb, Q, r] plane-wave amplitudes of each block's sources; parts: list of (kernel, values [N, r])."""
        out = None
        for kern, vals in parts:
            sf, sl = self._blocked(self.src[(direction, kern)])
            vf, vl = self._blocked(vals)
            arr = np.concatenate([np.matmul(sf.transpose(0, 2, 1), vf), (sl.T @ vl)[None]])
            out = arr if out is None else out + arr
        return out

    def apply(self, direction, parts, out):
        """Add the far contributions (sources two or more blocks away in ``direction``) to out [N, r]."""
        P = self.spectra(direction, parts)
        nb = self.nb
        accs = np.zeros_like(P)
        acc = np.zeros(P.shape[1:], complex)
        order = range(2, nb) if direction == "fwd" else range(nb - 3, -1, -1)
        step = -2 if direction == "fwd" else 2
        for j in order:
            acc = (acc + P[j + step]) * self.prop[j + step // 2][:, None]
            accs[j] = acc
        rf, rl = self._blocked(self.rcv[direction])
        of, ol = self._blocked(out)
        of += np.matmul(rf, accs[:-1])
        ol += rl @ accs[-1]


class _System:
    """A x = b of one polarisation, unknowns in block order: block j holds [kind 0 samples, kind 1 samples, ...].

    eqs: per equation, list of (kind, band [N, 2h+1] or None, coefficient, identity coefficient);
    far: per equation, list of (_Far, [(kernel, kind, coefficient), ...]).
    """

    def __init__(self, n, bounds, half, kinds, eqs, far):
        self.n, self.bounds, self.kinds = n, bounds, kinds
        nk = self.nk = len(kinds)
        nb = self.nb = bounds.size - 1
        self.start = nk * bounds
        lens = np.diff(bounds)
        # flat position of (kind or equation e, sample i)
        of = np.repeat(np.arange(nb), lens)
        local = np.arange(n) - bounds[of]
        self.idx = [self.start[of] + e * lens[of] + local for e in range(nk)]
        self.far_terms = far
        rows_all, cols_all, vals_all = [None] * nb, [None] * nb, [None] * nb
        self.Dinv, self.LoUp = [None] * nb, [None] * nb
        b = int(lens[0])
        # blocks whose neighbours exist and all have b samples: one gather and one batched inverse for all of them
        reg = [j for j in range(1, nb - 1) if lens[j - 1] == lens[j] == lens[j + 1] == b]
        if reg:
            self._regular_blocks(np.array(reg), b, half, kinds, eqs, rows_all, cols_all, vals_all)
        for j in range(nb):
            if self.Dinv[j] is None:
                slab, c0 = self._block(j, half, eqs)
                rows_all[j] = np.full(slab.shape[0], slab.shape[1])
                cols_all[j] = np.tile(np.arange(c0, c0 + slab.shape[1]), slab.shape[0])
                vals_all[j] = slab.ravel()
        N = nk * n
        indptr = np.concatenate([[0], np.cumsum(np.concatenate(rows_all))])
        self.near = scipy.sparse.csr_matrix((np.concatenate(vals_all), np.concatenate(cols_all), indptr), shape=(N, N))
        self._lu = None
        self._plans = {}
        # far channels (region, direction, equation, parts): factors read from the region's arrays block by block
        self.lens = lens
        self.channels = [(region, direction, e, parts) for e, terms in enumerate(far) for region, parts in terms
                         for direction in ("fwd", "bwd")]

    def _block(self, j, half, eqs):
        """One block row (at the partition ends, or beside a block of another length): its slab over the columns
        of blocks j-1 .. j+1 from the bands, the diagonal block's inverse Dinv_j and Dinv_j times the neighbours'
        columns (in self.Dinv, self.LoUp).  Returns (slab, its first column)."""
        bounds, kinds, nk, nb = self.bounds, self.kinds, self.nk, self.nb
        rows = np.arange(bounds[j], bounds[j + 1])
        blk = {}
        for jj in (j - 1, j, j + 1):
            if not 0 <= jj < nb:
                continue
            cols = np.arange(bounds[jj], bounds[jj + 1])
            off = cols[None, :] - rows[:, None] + half
            M = np.zeros((nk * rows.size, nk * cols.size), complex)
            for e, terms in enumerate(eqs):
                for kind, band, coef, ident in terms:
                    ki = kinds.index(kind)
                    sub = M[e * rows.size:(e + 1) * rows.size, ki * cols.size:(ki + 1) * cols.size]
                    if band is not None:
                        sub += coef * band[rows[:, None], off]
                    if ident and jj == j:
                        sub[np.arange(rows.size), np.arange(rows.size)] += ident
            blk[jj] = M
        # the row block's columns (blocks j-1 .. j+1) are contiguous in the block ordering: one dense slab
        slab = np.hstack([blk[jj] for jj in sorted(blk)])
        c0 = self.start[min(blk)]
        dinv = np.linalg.inv(blk[j])
        self.Dinv[j] = dinv
        # x_j = Dinv_j (rhs_j - A_{j,j-1} x_{j-1} - A_{j,j+1} x_{j+1}): the neighbours' part as one product
        # with the contiguous window of blocks j-1 .. j+1 (the middle block's columns zero)
        off = slab.copy()
        mid0 = self.start[j] - c0
        off[:, mid0:mid0 + blk[j].shape[1]] = 0.0
        self.LoUp[j] = (c0, c0 + slab.shape[1], dinv @ off) if nb > 1 else None
        return slab, c0

    def _regular_blocks(self, reg, b, half, kinds, eqs, rows_all, cols_all, vals_all):
        """Blocks j in ``reg`` (neighbours j - 1, j + 1 of b samples too), all at once: the row slab over the
        columns of blocks j-1 .. j+1 (kind-major within each block) gathered from the bands, the diagonal
        blocks inverted in one batched call, Dinv times the neighbours' columns."""
        nk = self.nk
        per = max(1, 32768 // (3 * nk * nk * b * b))          # blocks at a time (cache-sized)
        if reg.size > per:
            for g0 in range(0, reg.size, per):
                self._regular_blocks(reg[g0:g0 + per], b, half, kinds, eqs, rows_all, cols_all, vals_all)
            return
        nr = reg.size
        i = np.arange(b)
        off = (np.arange(3 * b) - b)[None, :] - i[:, None] + half            # [b, 3b], the same for every block
        rows = self.bounds[reg][:, None, None] + i[None, :, None]            # [nr, b, 1]
        M = np.zeros((nr, nk, b, 3, nk, b), complex)
        for e, terms in enumerate(eqs):
            for kind, band, coef, ident in terms:
                ki = kinds.index(kind)
                if band is not None:
                    M[:, e, :, :, ki, :] += coef * band[rows, off[None]].reshape(nr, b, 3, b)
                if ident:
                    M[:, e, i, 1, ki, i] += ident
        nkb = nk * b
        slab = M.reshape(nr, nkb, 3 * nkb)
        dinv = np.linalg.inv(np.ascontiguousarray(M[:, :, :, 1]).reshape(nr, nkb, nkb))
        offd = slab.copy()
        offd[:, :, nkb:2 * nkb] = 0.0
        loup = np.matmul(dinv, offd)
        c0s = self.start[reg - 1]
        for t, j in enumerate(reg):
            c0 = int(c0s[t])
            self.Dinv[j] = dinv[t]
            self.LoUp[j] = (c0, c0 + 3 * nkb, loup[t])
            rows_all[j] = np.full(nkb, 3 * nkb)
            cols_all[j] = np.tile(np.arange(c0, c0 + 3 * nkb), nkb)
            vals_all[j] = slab[t].ravel()

    def natural(self, xf, kind):
        """[N, r] values of one kind from the flat vector."""
        return xf[self.idx[self.kinds.index(kind)]]

    def far(self, xf, only=None):
        out = np.zeros_like(xf)
        for e, terms in enumerate(self.far_terms):
            acc = np.zeros((self.n, xf.shape[1]), complex)
            for region, parts in terms:
                vals = [(kern, coef * self.natural(xf, kind)) for kern, kind, coef in parts]
                for direction in ("fwd", "bwd") if only is None else (only,):
                    region.apply(direction, vals, acc)
            out[self.idx[e]] += acc
        return out

    def matvec(self, xf):
        return self.near @ xf + self.far(xf)

    def _plan(self, direction):
        """Per block: the receiver rows (with their equation) and transposed source rows (with kind index and
        coefficient) of every far channel of ``direction``; built once."""
        if direction not in self._plans:
            chans = [ch for ch in self.channels if ch[1] == direction]
            kind_of = {kind: i for i, kind in enumerate(self.kinds)}
            blocks = []
            for j in range(self.nb):
                samples = slice(self.bounds[j], self.bounds[j + 1])
                rc = [(region.rcv[direction][samples], e) for region, _, e, _ in chans]
                sc = [[(region.src[(direction, kern)][samples].T, kind_of[kind], coef) for kern, kind, coef in parts]
                      for region, _, _, parts in chans]
                blocks.append((rc, sc))
            self._plans[direction] = ([ch[0].prop for ch in chans], blocks)
        return self._plans[direction]

    def sweep(self, xf, bf, direction, ahead):
        """One block Gauss-Seidel sweep in ``direction`` (in place), the far part accumulated on the way.

        ``ahead``: the far contributions of the other direction for the current xf.  Returns this
        direction's far contributions for the new xf (block j's come from blocks two or more
        behind, final by the time j is solved): the ``ahead`` of the next sweep, free.
        """
        nb = self.nb
        c = bf - ahead
        own = np.zeros_like(xf)
        st = self.start
        fwd = direction == "fwd"
        order = range(nb) if fwd else range(nb - 1, -1, -1)
        props, blocks = self._plan(direction)
        nch = len(props)
        accs = [None] * nch
        pend = [[None] * nb for _ in range(nch)]
        behind, mid_step = (-2, -1) if fwd else (2, 1)
        for step, j in enumerate(order):
            s0, s1 = st[j], st[j + 1]
            L = self.lens[j]
            rc, sc = blocks[j]
            rhs = c[s0:s1]
            if step >= 2 and nch:
                o = own[s0:s1]
                for t in range(nch):
                    a = pend[t][j + behind]
                    if accs[t] is not None:
                        a += accs[t]
                    a *= props[t][j + mid_step][:, None]
                    accs[t] = a
                    rcv, e = rc[t]
                    o[e * L:(e + 1) * L] += rcv @ a
                rhs = rhs - o
            xj = self.Dinv[j] @ rhs
            lu = self.LoUp[j]
            if lu is not None:
                xj -= lu[2] @ xf[lu[0]:lu[1]]
            xf[s0:s1] = xj
            for t in range(nch):
                acc = None
                for srcT, ki, coef in sc[t]:
                    part = srcT @ xj[ki * L:(ki + 1) * L]
                    if coef != 1.0:
                        part *= coef
                    if acc is None:
                        acc = part
                    else:
                        acc += part
                pend[t][j] = acc
        return own

    def lu(self):
        if self._lu is None:
            self._lu = scipy.sparse.linalg.splu(self.near.tocsc(), permc_spec="NATURAL", diag_pivot_thresh=1.0)
        return self._lu


def _rel_residual(sys, xf, bf, bwd=None):
    """||b - A x|| / ||b|| per right-hand side (``bwd``: the backward far part of x, if known)."""
    if bwd is None:
        bwd = sys.far(xf, only="bwd")
    r = bf - sys.near @ xf
    r -= sys.far(xf, only="fwd")
    r -= bwd
    den = np.linalg.norm(bf, axis=0)
    return np.linalg.norm(r, axis=0) / np.where(den > 0, den, 1.0)


def _relative_step(xf, prev):
    """||x - x_prev|| / ||x|| per right-hand side; ``prev`` becomes x (in place)."""
    size = np.linalg.norm(xf, axis=0)
    prev -= xf
    step = np.linalg.norm(prev, axis=0) / np.where(size > 0, size, 1.0)
    prev[...] = xf
    return step


def _estimate_worth_checking(res, tol, history):
    """Whether the estimated residual says converged, rising (above 1.5x the best) or stalling (above 0.8x
    three sweeps back): then the true residual is computed."""
    e = float(res.max())
    return e <= tol or e > 1.5 * min(history) or (len(history) >= 3 and e > 0.8 * history[-3])


def _divergence_or_stall(history, it):
    """Why the sweeps stop at sweep ``it`` (0-based) -- the residual rose above 1.5x its best, or fell by less
    than 20 % over 3 sweeps -- or None."""
    if it >= 1 and history[-1] > 1.5 * min(history[:-1]):
        return (f"the forward-backward iteration diverges (residual {min(history):.2g} -> "
                f"{history[-1]:.2g} at sweep {it + 1})")
    if it >= 3 and history[-1] > 0.8 * history[-4]:
        return (f"the forward-backward iteration stalls (residual {history[-4]:.2g} -> "
                f"{history[-1]:.2g} over 3 sweeps)")
    return None


def _forward_backward(sys, bf, tol, max_sweeps, info):
    """Forward-backward sweeps from x = 0 until the residual is <= tol.  Returns (x, residuals, None) when
    converged, else (the best iterate, its residuals, why the sweeps stopped)."""
    xf = np.zeros_like(bf)
    history = []
    best_x, best = xf.copy(), np.ones(bf.shape[1])          # x = 0 has residual 1
    ahead = np.zeros_like(bf)               # the far part of x = 0
    prev = xf.copy()
    checked = None                          # (residual, step) of the last sweep whose residual was computed
    info["residual_checks"] = 0
    for it in range(max_sweeps):
        ahead = sys.sweep(xf, bf, "bwd", sys.sweep(xf, bf, "fwd", ahead))
        info["sweeps"] = it + 1
        step = _relative_step(xf, prev)
        exact = checked is None or it < 2 or it == max_sweeps - 1 or not np.all(np.isfinite(step))
        if not exact:
            # a linearly converging iteration's residual falls as its step: estimate it from the last check,
            # and compute it where the estimate says converged, rising or stalling (a full product saved
            # on the other sweeps)
            res = checked[0] * step / np.where(checked[1] > 0, checked[1], 1.0)
            exact = _estimate_worth_checking(res, tol, history)
        if exact:
            res = _rel_residual(sys, xf, bf, bwd=ahead)
            checked = (res, step)
            info["residual_checks"] += 1
        if not np.all(np.isfinite(res)):
            return best_x, best, f"the forward-backward iteration produced non-finite values at sweep {it + 1}"
        history.append(float(res.max()))
        if not exact:
            continue
        better = res < best
        best_x[:, better] = xf[:, better]
        best = np.minimum(best, res)
        if res.max() <= tol:
            return xf, res, None
        why = _divergence_or_stall(history, it)
        if why is not None:
            return best_x, best, why
    return best_x, best, f"the forward-backward iteration reached {max_sweeps} sweeps at residual {history[-1]:.2g}"


def _gmres(sys, bf, xf, res, tol, info):
    """Restarted GMRES (60, at most 5 restarts) on every right-hand side whose residual is above tol, from xf,
    preconditioned by the sparse LU of the strong part; xf is updated in place."""
    lu = sys.lu()
    N = bf.shape[0]
    A = scipy.sparse.linalg.LinearOperator((N, N), matvec=lambda f: sys.matvec(f.reshape(-1, 1)).ravel(),
                                           dtype=complex)
    M = scipy.sparse.linalg.LinearOperator((N, N), matvec=lambda f: lu.solve(np.asarray(f, complex)), dtype=complex)
    for c in range(bf.shape[1]):
        if res[c] <= tol:
            continue
        count = [0]

        def cb(_):
            count[0] += 1

        sol, _ = scipy.sparse.linalg.gmres(A, bf[:, c], x0=xf[:, c], rtol=0.5 * tol, atol=0.0, restart=60,
                                           maxiter=5, M=M, callback=cb, callback_type="pr_norm")
        info["gmres_iterations"] += count[0]
        xf[:, c] = sol


def _iterate(sys, bf, tol, max_sweeps, method, reasons, label):
    """Forward-backward sweeps, then GMRES where they fail; returns x, per-rhs residuals, info."""
    info = {"sweeps": 0, "gmres_iterations": 0, "method": "fb"}
    xf, res = np.zeros_like(bf), np.full(bf.shape[1], np.inf)
    if method == "fb":
        xf, res, why = _forward_backward(sys, bf, tol, max_sweeps, info)
        if why is None:
            return xf, res, info
        reasons.append(f"{label}: {why} (tolerance {tol:g}); GMRES takes over")
    info["method"] = "gmres"
    _gmres(sys, bf, xf, res, tol, info)
    return xf, _rel_residual(sys, xf, bf), info


def block_length_wl(height_wl, ks, near_wl=NEAR_WL, growth=BLOCK_GROWTH):
    """Shortest block (wavelengths) over which the plane-wave sums of every k in ``ks`` grow by at most e^growth
    across a height range ``height_wl``: k H^2 / (4 L_s) <= growth, and at least ``near_wl``."""
    return max(near_wl, max(abs(complex(k)) for k in ks) * height_wl ** 2 / (4.0 * growth))


def plan_blocks(n, dx, height, length, ks, near_wl):
    """Block samples b and the plane-wave rule of every k in ``ks``; where a rule misses its tolerance (rounding
    in the sum's growth), the blocks are lengthened (growth x 0.75, up to three times) rather than given up."""
    growth = BLOCK_GROWTH
    for attempt in range(4):
        b = max(8, int(math.ceil(block_length_wl(height, ks, near_wl, growth) / dx)))
        if 3 * b > n:
            raise FastSolverUnsuitable(
                f"blocks of {b * dx:.3g} wavelengths (height range {height:.3g}) leave fewer than 3 blocks in a "
                f"partition of {length:.3g} wavelengths")
        try:
            return b, [spectral_rule(k, (b - 1) * dx, length, height) for k in ks]
        except _RuleShort:
            if attempt == 3:
                raise
            growth *= 0.75


def _equations(pol, eta, S0, D0, S1, D1, far0, far1):
    """(kinds, eqs, far) of one polarisation for :class:`_System` (module docstring): a PEC's EFIE
    ``S0 v = psi`` (s) or MFIE ``(1/2 - D0) u = psi`` (p); a finite index's coupled pair
    ``(1/2 - D0) u + S0 v = psi``, ``(1/2 + D1) u - rho S1 v = 0`` (rho = 1 in s, eta^2 in p)."""
    if eta is None:
        if pol == "s":
            return ["v"], [[("v", S0, 1.0, 0.0)]], [[(far0, [("S", "v", 1.0)])]]
        return ["u"], [[("u", D0, -1.0, 0.5)]], [[(far0, [("D", "u", -1.0)])]]
    rho = 1.0 if pol == "s" else eta * eta
    eqs = [[("u", D0, -1.0, 0.5), ("v", S0, 1.0, 0.0)],
           [("u", D1, 1.0, 0.5), ("v", S1, -rho, 0.0)]]
    far = [[(far0, [("S", "v", 1.0), ("D", "u", -1.0)])],
           [(far1, [("S", "v", -rho), ("D", "u", 1.0)])] if far1 is not None else []]
    return ["u", "v"], eqs, far


def _partition_plan(x, y, dx, eta, near_wl):
    """The partition's blocks and plane-wave rules: a metal's interior operators end within a few skin depths
    (banded, no far part); glass's reach beyond a block and get their own rule.  Returns (blocks, rules,
    interior_far)."""
    n = x.size
    height = float(y.max() - y.min())
    length = float(x[-1] - x[0] + dx)
    k1 = None if eta is None else K0 * eta
    band1 = n if k1 is None or k1.imag == 0 else int(math.ceil(DECAY_CUTOFF / (abs(k1.imag) * dx)))
    interior_far = k1 is not None and band1 >= max(8, int(math.ceil(block_length_wl(height, [K0], near_wl) / dx))) - 1
    ks = [K0, k1] if interior_far else [K0]
    b, rules = plan_blocks(n, dx, height, length, ks, near_wl)
    return _Blocks(n, b), rules, interior_far


def _operators(x, yc, fp, fpp, dx, eta, pols, blocks, rules, interior_far, info):
    """The strong (band) and far parts of the exterior (k0) and, for a finite index, the interior (k0 eta)
    operators: (S0, D0, S1, D1, far0, far1), None where not needed."""
    bounds, half = blocks.bounds, 2 * blocks.width + 1
    need0S = eta is not None or "s" in pols
    need0D = eta is not None or "p" in pols
    phi, w = rules[0]
    info["plane_waves"] = phi.size
    S0, D0, _ = _band_fill(x, yc, fp, fpp, dx, K0, bounds, half, need0S, need0D)
    far0 = _Far(x, yc, fp, dx, K0, bounds, phi, w, need0S, need0D)
    S1 = D1 = far1 = None
    if eta is not None:
        k1 = K0 * eta
        S1, D1, _ = _band_fill(x, yc, fp, fpp, dx, k1, bounds, half, True, True)
        if interior_far:
            phi1, w1 = rules[1]
            far1 = _Far(x, yc, fp, dx, k1, bounds, phi1, w1, True, True)
            info["plane_waves_interior"] = phi1.size
    return S0, D0, S1, D1, far0, far1


def solve_fast(x, y, fp, fpp, dx, psi, pols, eta, *, tol=FAST_TOL, method="fb", near_wl=NEAR_WL,
               max_sweeps=MAX_SWEEPS):
    """Surface fields of one partition by the fast solver (module docstring), all incidence angles at once.

    Parameters
    ----------
    x, y, fp, fpp : ndarray [N], sample abscissae (uniform step dx, local coordinates), heights,
        slopes and curvatures (wavelengths); psi : [N, n_ti] incident field at the samples.
    pols : tuple of "s"/"p"; eta : None (PEC) or the index n - j kappa.
    tol : relative residual ||b - A x|| / ||b|| to reach; method : "fb" (forward-backward
        sweeps, GMRES if they fail) or "gmres" (GMRES from the start).
    near_wl : shortest block (strong region) in wavelengths.

    Returns
    -------
    dict: per polarisation P, ``u_P``, ``v_P`` [N, n_ti] (None where zero: a PEC), and ``info``:
    block size, plane waves Q, per polarisation the method that finished, sweeps, GMRES
    iterations and final residuals, ``converged`` (all residuals <= tol) and ``reasons``
    (every fallback, with why).

    Raises FastSolverUnsuitable where the surface is too rough for the plane-wave sums.
    """
    if method not in ("fb", "gmres"):
        raise UsageError(f"method must be 'fb' or 'gmres', got {shorten(method)}")
    clock = time.process_time
    t0 = clock()
    t_solve = 0.0
    n = x.size
    yc = y - 0.5 * (y.max() + y.min())
    blocks, rules, interior_far = _partition_plan(x, y, dx, eta, near_wl)
    reasons = []
    info = {"block_samples": blocks.b, "blocks": blocks.nb, "reasons": reasons}   # far sources: >= (b - 1) dx away
    S0, D0, S1, D1, far0, far1 = _operators(x, yc, fp, fpp, dx, eta, pols, blocks, rules, interior_far, info)
    out = {"info": info}
    for pol in pols:
        sys = None                      # the previous polarisation's system goes before the next is built
        kinds, eqs, far = _equations(pol, eta, S0, D0, S1, D1, far0, far1)
        sys = _System(n, blocks.bounds, 2 * blocks.width + 1, kinds, eqs, far)
        bf = np.zeros((sys.nk * n, psi.shape[1]), complex)
        bf[sys.idx[0]] = psi
        ta = clock()
        sol, res, pinfo = _iterate(sys, bf, tol, max_sweeps, method, reasons, f"{pol}-pol")
        t_solve += clock() - ta
        pinfo["residual"] = res
        info[pol] = pinfo
        if eta is None:
            u_v = sys.natural(sol, kinds[0])
            out["u_" + pol], out["v_" + pol] = (None, u_v) if pol == "s" else (u_v, None)
        else:
            out["u_" + pol], out["v_" + pol] = sys.natural(sol, "u"), sys.natural(sol, "v")
    info["converged"] = all(np.all(info[p]["residual"] <= tol) for p in pols)
    info["times"] = {"setup": clock() - t0 - t_solve, "solve": t_solve}
    return out
