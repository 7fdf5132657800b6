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
  of distances and heights before it is used.  Each source cell is integrated exactly
  per plane wave against the quadratic interpolant of the samples (the dense path's
  cell moments), the double layer carries j k (sin phi - f' cos phi).  A block's
  sources are summed into Q plane-wave amplitudes, propagated block to block by
  exp(-j k L cos phi) and evaluated at the receivers: O(N Q) per product, in both
  directions (the backward one on the mirrored surface).
* **Forward-backward iteration**: a block symmetric Gauss-Seidel sweep (forward
  through the blocks with the updated values behind and the previous ones ahead, then
  backward), the method of moments' "forward-backward method" (FBM), all incidence
  angles at once.  After each sweep the true residual ||b - A x|| / ||b|| is computed
  (one full product); below ``tol`` it stops.
* **Guards**: a sweep that raises the residual (a steep or re-entrant realisation,
  multiple scattering that the sweep order cannot follow) or stalls (less than 10 %
  gain per sweep over three sweeps), or ``max_sweeps`` reached, hands the best iterate
  to restarted GMRES preconditioned by the sparse LU of the strong part (the same fast
  product); if GMRES does not reach ``tol`` either, the caller falls back to the
  dense LU where it fits (:mod:`hyde_bsdf.mom.solver`), and every step says why in
  ``info["reasons"]``.

Limits: the plane-wave sum needs k H^2 / (4 L_s) <= 25 (H the partition's height
range, L_s the block length), so a very rough surface gets long blocks, and when the
block would exceed a third of the partition the fast solver declines
(:class:`FastSolverUnsuitable`).  A lossy interior (a metal) is banded and needs no far
part; a lossless or weakly lossy one (glass) gets its own spectral far part with
k1 = k0 eta, on the contour turned by -arg(k1)/2 (the steepest-descent line of a lossy
saddle); a rule whose plane waves would grow along x, or that does not reach its tolerance
(eta = 0.5 - 0.3j on a surface with a 4.5-lambda height range stalls at 1.6e-4: the turned
line's truncation), is refused and the partition goes to the dense LU with the reason.
"""
from __future__ import annotations

import math
import time

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from hyde_bsdf.mom.kernels import (
    DECAY_CUTOFF, K0, _cell_moments, _complex_weights, _interp_weights, _near, _self, _sinc_derivatives, hankel2,
)

__all__ = ["solve_fast", "spectral_rule", "FastSolverUnsuitable", "FAST_TOL", "NEAR_WL"]

#: default relative residual ||b - A x|| / ||b|| at which the iteration stops
FAST_TOL = 1e-4
#: shortest block (strong-interaction length) in wavelengths
NEAR_WL = 3.0
#: largest exp(k H^2 / (4 L_s)) growth of the plane-wave sum allowed (digits lost: GROWTH / ln 10)
GROWTH_MAX = 25.0
#: sweeps of the forward-backward iteration before GMRES takes over
MAX_SWEEPS = 30
_NEAR = 4  # near-cell offsets integrated by Gauss-Legendre (as kernels.layer_matrices)


class FastSolverUnsuitable(ValueError):
    """The surface is too rough (height range against partition length) for the spectral far part."""


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
    h_far = min(0.06, 1.0 / (kk * max(height_wl, 0.5)))
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
    raise FastSolverUnsuitable(f"no plane-wave rule reached {tol:g} (best {err:.2g}) for k={k}, blocks of "
                               f"{near_wl:.3g}, length {length_wl:.3g}, height range {height_wl:.3g}")


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
    nb = bounds.size - 1
    for j in range(nb):
        a, b = bounds[j], bounds[j + 1]
        lo, hi = bounds[max(j - 1, 0)], bounds[min(j + 2, nb)]      # the columns kept
        c0, c1 = max(lo - 1, 0), min(hi + 1, n)                     # cells that reach them
        m = np.arange(a, b)[:, None]
        cell = np.arange(c0, c1)[None, :]
        sep = np.abs(cell - m)
        inside = (sep > _NEAR) & (sep <= band)
        ddx = x[c0:c1][None, :] - x[a:b, None]
        ddy = y[c0:c1][None, :] - y[a:b, None]
        R = np.where(inside, np.hypot(ddx, ddy), 1.0)  # guard: near/self cells are integrated apart
        fpc = fp[c0:c1][None, :]
        kr = k * R
        ws = wd = None
        if decay == 0.0:
            drdt = (ddx + ddy * fpc) / R
            sd = _sinc_derivatives((0.5 * k * dx) * drdt)
            eps = (-0.5 * dx) * drdt / R
            if need_S:
                ws = _interp_weights(np.where(inside, (-0.25j * dx) * hankel2(0, kr), 0.0), sd, eps)
            if need_D:
                K = np.where(inside, (0.25j * k * dx) * hankel2(1, kr) * (-fpc * ddx + ddy) / R, 0.0)
                wd = _interp_weights(K, sd, 3.0 * eps)
        else:
            drdt = (0.5j * dx) * (ddx + ddy * fpc) / R
            h0 = hankel2(0, kr)
            h1 = hankel2(1, kr)
            if need_S:
                ws = _complex_weights(np.where(inside, (-0.25j * dx) * h0, 0.0),
                                      _cell_moments(drdt * (-k) * h1 / h0))
            if need_D:
                K = np.where(inside, (0.25j * k * dx) * h1 * (-fpc * ddx + ddy) / R, 0.0)
                wd = _complex_weights(K, _cell_moments(drdt * (k * h0 / h1 - 2.0 / R)))
        for M, wts in ((S, ws), (D, wd)):
            if M is None:
                continue
            w0, wp, wm = wts
            # rectangle over columns c0 - 1 .. c1: v_{n+1} weights one to the right, v_{n-1} one to the left
            rect = np.zeros((b - a, c1 - c0 + 2), complex)
            rect[:, 1:-1] += w0
            rect[:, 2:] += wp
            rect[:, :-2] += wm
            if c1 == n:                      # partition ends: folded into the end cell's column
                rect[:, -2] += rect[:, -1]
            if c0 == 0:
                rect[:, 1] += rect[:, 0]
            cols = np.arange(lo, hi)
            M[a:b][np.arange(b - a)[:, None], cols[None, :] - m + half] = rect[:, cols - c0 + 1]
    offsets = [o for o in range(-_NEAR, _NEAR + 1) if o != 0 and abs(o) < n]
    SA = _BandStore(S, half) if need_S else None
    DA = _BandStore(D, half) if need_D else None
    _near(x, y, fp, fpp, dx, k, offsets, need_S, need_D, SA, DA)
    _self(x, y, fp, fpp, dx, k, need_S, need_D, SA, DA)
    return S, D, band


# ---------------------------------------------------------------------------
# The weak part: plane-wave sums block to block
# ---------------------------------------------------------------------------

def _moments(a):
    """Cell moments m0, m1, m2 of kernels._cell_moments for complex a, from one complex exponential.

    m0 = sin a / a, m1 = (j/2) (a cos a - sin a) / a^2, m2 = -(1/4) ((2 - a^2) sin a - 2 a cos a) / a^3,
    Taylor series where |a| < 0.2.
    """
    small = np.abs(a) < 0.2
    ag = np.where(small, 1.0, a)
    e = np.exp(1j * ag)
    ei = 1.0 / e
    sa = (e - ei) * -0.5j
    ca = (e + ei) * 0.5
    inv = 1.0 / ag
    m0 = sa * inv
    d1 = (ca - m0) * inv
    d2 = ((2.0 - ag * ag) * sa - 2.0 * ag * ca) * inv * inv * inv
    if np.any(small):
        b = a[small]
        b2 = b * b
        m0[small] = 1.0 - b2 / 6.0 + b2 * b2 / 120.0 - b2 ** 3 / 5040.0
        d1[small] = b * (-1.0 / 3.0 + b2 / 30.0 - b2 * b2 / 840.0)
        d2[small] = -1.0 / 3.0 + b2 / 10.0 - b2 * b2 / 168.0
    return m0, 0.5j * d1, -0.25 * d2


def _direction_factors(x, y_factor, fp, dx, k, bounds, cphi, sphi, w, need_S, need_D):
    """Receiver and source factors of the plane-wave sums for receivers right of their sources.

    Returns rcv [N, Q] (times the rule's weights and -j/(4 pi)), src_S, src_D [N, Q] (each
    column's three cells integrated against the quadratic interpolant, the partition ends
    folded as in the dense path) and prop [nb, Q] (exp(-j k L cos phi) across each block).
    ``y_factor`` is exp(j k y sin phi) [N, Q] (shared by both directions).
    """
    nb = bounds.size - 1
    of = np.repeat(np.arange(nb), np.diff(bounds))
    edges = np.append(x[bounds[:-1]] - 0.5 * dx, x[-1] + 0.5 * dx)
    prop = np.exp(-1j * k * np.diff(edges)[:, None] * cphi[None, :])
    left, right = edges[of], edges[of + 1]
    rcv = np.exp(-1j * k * (x - left)[:, None] * cphi[None, :])
    rcv /= y_factor
    rcv *= (-0.25j / math.pi) * w
    out = {"rcv": rcv, "prop": prop, "S": None, "D": None}
    if not (need_S or need_D):
        return out
    # each cell's plane-wave factor relative to the right edge of its own block
    e_cell = np.exp(1j * k * (x - right)[:, None] * cphi[None, :])
    e_cell *= y_factor
    w0, wp, wm = _complex_weights(dx, _moments(-0.5 * k * dx * (cphi[None, :] + fp[:, None] * sphi[None, :])))
    dfac = 1j * k * (sphi[None, :] - fp[:, None] * cphi[None, :]) if need_D else None
    first = bounds[1:-1]          # first sample of blocks 1..nb-1
    for name, need in (("S", need_S), ("D", need_D)):
        if not need:
            continue
        g = e_cell if name == "S" else e_cell * dfac
        acc = w0 * g
        acc[1:] += wp[:-1] * g[:-1]       # cell c - 1's v_{n+1} weight, to column c
        acc[:-1] += wm[1:] * g[1:]        # cell c + 1's v_{n-1} weight, to column c
        acc[0] += wm[0] * g[0]            # partition ends: folded into the end cell's column
        acc[-1] += wp[-1] * g[-1]
        # across block edges the reference is the column's block's right edge
        if first.size:
            # column first[i] got cell first[i]-1 (previous block, reference one block to the left)
            acc[first] += wp[first - 1] * g[first - 1] * (prop[of[first]] - 1.0)
            # column first[i]-1 got cell first[i] (next block): recompute against the left block's edge
            c = first - 1
            ec = np.exp(1j * k * (x[first] - right[c])[:, None] * cphi[None, :]) * y_factor[first]
            if name == "D":
                ec *= dfac[first]
            acc[c] += wm[first] * (ec - g[first])
        out[name] = acc
    return out


class _Far:
    """Far part of one region's S and D, both directions, in the natural sample order.

    The backward direction is computed on the mirrored surface (x -> -x, order reversed,
    f' -> -f': the double layer keeps its form) and its factors are put back in natural order.
    """

    def __init__(self, x, y, fp, dx, k, bounds, phi, w, need_S, need_D):
        cphi, sphi = np.cos(phi), np.sin(phi)
        yf = np.exp(1j * k * y[:, None] * sphi[None, :])
        self.q = phi.size
        self.bounds = bounds
        self.nb = bounds.size - 1
        f = _direction_factors(x, yf, fp, dx, k, bounds, cphi, sphi, w, need_S, need_D)
        mb = x.size - bounds[::-1]
        b = _direction_factors(-x[::-1], yf[::-1], -fp[::-1], dx, k, mb, cphi, sphi, w, need_S, need_D)
        self.rcv = {"fwd": f["rcv"], "bwd": b["rcv"][::-1]}
        self.src = {("fwd", "S"): f["S"], ("fwd", "D"): f["D"],
                    ("bwd", "S"): None if b["S"] is None else b["S"][::-1],
                    ("bwd", "D"): None if b["D"] is None else b["D"][::-1]}
        self.prop = f["prop"]      # across block j (the same length whichever way)

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
        rows_all, cols_all, vals_all = [], [], []
        self.Dinv, self.Lo, self.Up = [], [], []
        for j in range(nb):
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
            rows_all.append(np.full(slab.shape[0], slab.shape[1]))
            cols_all.append(np.tile(np.arange(c0, c0 + slab.shape[1]), slab.shape[0]))
            vals_all.append(slab.ravel())
            self.Dinv.append(np.linalg.inv(blk[j]))
            self.Lo.append(self.Dinv[j] @ blk[j - 1] if j > 0 else None)
            self.Up.append(self.Dinv[j] @ blk[j + 1] if j < nb - 1 else None)
        N = nk * n
        indptr = np.concatenate([[0], np.cumsum(np.concatenate(rows_all))])
        self.near = scipy.sparse.csr_matrix((np.concatenate(vals_all), np.concatenate(cols_all), indptr), shape=(N, N))
        self._lu = None
        # far channels (region, direction, equation, parts): factors read from the region's arrays block by block
        self.lens = lens
        self.channels = [(region, direction, e, parts) for e, terms in enumerate(far) for region, parts in terms
                         for direction in ("fwd", "bwd")]

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

    def sweep(self, xf, bf, direction, ahead=None):
        """One block Gauss-Seidel sweep in ``direction`` (in place), the far part accumulated on the way.

        ``ahead``: the far contributions of the other direction for the current xf, if known.
        """
        nb = self.nb
        if ahead is None:
            ahead = self.far(xf, only="bwd" if direction == "fwd" else "fwd")
        c = bf - ahead
        st = self.start
        fwd = direction == "fwd"
        order = range(nb) if fwd else range(nb - 1, -1, -1)
        r = xf.shape[1]
        chans = [ch for ch in self.channels if ch[1] == direction]
        accs = [np.zeros((ch[0].q, r), complex) for ch in chans]
        pend = [[None] * nb for _ in chans]
        kind_of = {kind: i for i, kind in enumerate(self.kinds)}
        for step, j in enumerate(order):
            s = slice(st[j], st[j + 1])
            rhs = c[s]
            if step >= 2:
                rhs = rhs.copy()
                src_blk = j - 2 if fwd else j + 2
                mid = j - 1 if fwd else j + 1
                samples = slice(self.bounds[j], self.bounds[j + 1])
                L = self.lens[j]
                for t, (region, _, e, _) in enumerate(chans):
                    accs[t] = (accs[t] + pend[t][src_blk]) * region.prop[mid][:, None]
                    rhs[e * L:(e + 1) * L] -= region.rcv[direction][samples] @ accs[t]
            xj = self.Dinv[j] @ rhs
            if j > 0:
                xj -= self.Lo[j] @ xf[st[j - 1]:st[j]]
            if j < nb - 1:
                xj -= self.Up[j] @ xf[st[j + 1]:st[j + 2]]
            xf[s] = xj
            samples = slice(self.bounds[j], self.bounds[j + 1])
            L = self.lens[j]
            for t, (region, _, _, parts) in enumerate(chans):
                acc = 0.0
                for kern, kind, coef in parts:
                    ki = kind_of[kind]
                    acc = acc + region.src[(direction, kern)][samples].T @ (coef * xj[ki * L:(ki + 1) * L])
                pend[t][j] = acc
        return xf

    def lu(self):
        if self._lu is None:
            self._lu = scipy.sparse.linalg.splu(self.near.tocsc(), permc_spec="NATURAL", diag_pivot_thresh=1.0)
        return self._lu


def _rel_residual(sys, xf, bf, keep=False):
    """||b - A x|| / ||b|| per right-hand side (keep=True: also the backward far part, for the next sweep)."""
    bwd = sys.far(xf, only="bwd")
    r = bf - sys.near @ xf - sys.far(xf, only="fwd") - bwd
    den = np.linalg.norm(bf, axis=0)
    res = np.linalg.norm(r, axis=0) / np.where(den > 0, den, 1.0)
    return (res, bwd) if keep else res


def _iterate(sys, bf, tol, max_sweeps, method, reasons, label):
    """Forward-backward sweeps, then GMRES where they fail; returns x, per-rhs residuals, info."""
    r = bf.shape[1]
    xf = np.zeros_like(bf)
    info = {"sweeps": 0, "gmres_iterations": 0, "method": "fb"}
    history = []
    best_x, best = xf.copy(), np.ones(r)          # x = 0 has residual 1
    res = None
    if method == "fb":
        why = None
        ahead = None
        for it in range(max_sweeps):
            sys.sweep(xf, bf, "fwd", ahead)
            sys.sweep(xf, bf, "bwd")
            res, ahead = _rel_residual(sys, xf, bf, keep=True)
            info["sweeps"] = it + 1
            if not np.all(np.isfinite(res)):
                why = f"the forward-backward iteration produced non-finite values at sweep {it + 1}"
                break
            history.append(float(res.max()))
            better = res < best
            best_x[:, better] = xf[:, better]
            best = np.minimum(best, res)
            if res.max() <= tol:
                return xf, res, info
            if it >= 1 and history[-1] > 1.5 * min(history[:-1]):
                why = (f"the forward-backward iteration diverges (residual {min(history):.2g} -> "
                       f"{history[-1]:.2g} at sweep {it + 1})")
                break
            if it >= 3 and history[-1] > 0.8 * history[-4]:
                why = (f"the forward-backward iteration stalls (residual {history[-4]:.2g} -> "
                       f"{history[-1]:.2g} over 3 sweeps)")
                break
        else:
            why = f"the forward-backward iteration reached {max_sweeps} sweeps at residual {history[-1]:.2g}"
        reasons.append(f"{label}: {why} (tolerance {tol:g}); GMRES takes over")
        xf, res = best_x, best
    info["method"] = "gmres"
    lu = sys.lu()
    N = bf.shape[0]
    A = scipy.sparse.linalg.LinearOperator((N, N), matvec=lambda f: sys.matvec(f.reshape(-1, 1)).ravel(),
                                           dtype=complex)
    M = scipy.sparse.linalg.LinearOperator((N, N), matvec=lambda f: lu.solve(np.asarray(f, complex)), dtype=complex)
    if res is None:
        res = np.full(r, np.inf)
    for c in range(r):
        if res[c] <= tol:
            continue
        count = [0]

        def cb(_):
            count[0] += 1

        sol, _ = scipy.sparse.linalg.gmres(A, bf[:, c], x0=xf[:, c], rtol=0.5 * tol, atol=0.0, restart=60,
                                           maxiter=5, M=M, callback=cb, callback_type="pr_norm")
        info["gmres_iterations"] += count[0]
        xf[:, c] = sol
    return xf, _rel_residual(sys, xf, bf), info


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
        raise ValueError(f"method must be 'fb' or 'gmres', got {method!r}")
    clock = time.process_time
    t0 = clock()
    t_solve = 0.0
    n = x.size
    yc = y - 0.5 * (y.max() + y.min())
    height = float(y.max() - y.min())
    length = float(x[-1] - x[0] + dx)
    k0 = K0
    k1 = None if eta is None else k0 * eta
    # a metal's interior operators end within a few skin depths (banded); glass's reach the whole partition
    band1 = n if k1 is None or k1.imag == 0 else int(math.ceil(DECAY_CUTOFF / (abs(k1.imag) * dx)))
    ks = [k0]
    lblock = near_wl
    # blocks: >= near_wl and long enough that the plane-wave sums grow by at most e^(0.8 GROWTH_MAX)
    lblock = max(lblock, k0 * height ** 2 / (4.0 * 0.8 * GROWTH_MAX))
    b = max(8, int(math.ceil(lblock / dx)))
    interior_far = k1 is not None and band1 >= b - 1
    if interior_far:
        ks.append(k1)
        lblock = max(lblock, abs(k1) * height ** 2 / (4.0 * 0.8 * GROWTH_MAX))
        b = max(b, int(math.ceil(lblock / dx)))
    if 3 * b > n:
        raise FastSolverUnsuitable(
            f"blocks of {b * dx:.3g} wavelengths (height range {height:.3g}) leave fewer than 3 blocks in a "
            f"partition of {length:.3g} wavelengths")
    blocks = _Blocks(n, b)
    bounds = blocks.bounds
    near_len = (b - 1) * dx          # shortest far separation: sources two blocks away
    half = 2 * blocks.width + 1
    reasons = []
    info = {"block_samples": b, "blocks": blocks.nb, "reasons": reasons}
    need0S = eta is not None or "s" in pols
    need0D = eta is not None or "p" in pols
    phi, w = spectral_rule(k0, near_len, length, height)
    info["plane_waves"] = phi.size
    S0, D0, _ = _band_fill(x, yc, fp, fpp, dx, k0, bounds, half, need0S, need0D)
    far0 = _Far(x, yc, fp, dx, k0, bounds, phi, w, need0S, need0D)
    far1 = None
    if eta is not None:
        S1, D1, _ = _band_fill(x, yc, fp, fpp, dx, k1, bounds, half, True, True)
        if interior_far:
            phi1, w1 = spectral_rule(k1, near_len, length, height)
            far1 = _Far(x, yc, fp, dx, k1, bounds, phi1, w1, True, True)
            info["plane_waves_interior"] = phi1.size
    out = {"info": info}
    for pol in pols:
        if eta is None:
            if pol == "s":
                kinds, eqs = ["v"], [[("v", S0, 1.0, 0.0)]]
                far = [[(far0, [("S", "v", 1.0)])]]
            else:
                kinds, eqs = ["u"], [[("u", D0, -1.0, 0.5)]]
                far = [[(far0, [("D", "u", -1.0)])]]
        else:
            rho = 1.0 if pol == "s" else eta * eta
            kinds = ["u", "v"]
            eqs = [[("u", D0, -1.0, 0.5), ("v", S0, 1.0, 0.0)],
                   [("u", D1, 1.0, 0.5), ("v", S1, -rho, 0.0)]]
            far = [[(far0, [("S", "v", 1.0), ("D", "u", -1.0)])],
                   [(far1, [("S", "v", -rho), ("D", "u", 1.0)])] if far1 is not None else []]
        sys = _System(n, bounds, half, kinds, eqs, far)
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
