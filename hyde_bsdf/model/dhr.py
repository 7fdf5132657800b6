"""Directional-hemispherical reflectance of the specular lobe of a PEC (paper Eqs. 14-16)
and the (theta_i, rms_slope) table the diffuse term reads, shipped as data.

rho^{s,PEC}(theta_i; s) = int F_00^{s,PEC} cos(theta_r) d omega_r          (Eq. 14, 16)

Quadrature in facet-slope space
-------------------------------
Over (theta_r, phi) the integrand is a narrow lobe for small s and is cut by the
horizon at grazing incidence.  Changing variables to the facet slopes (p, q)
(facet normal h ~ (-p, -q, 1), incidence in the x-z plane) turns Eq. 14 into an
expectation over the Gaussian slope density g (std s per axis, Eq. 8 times
cos^3 alpha):

    rho = int int g(p, q) W(p, q) dp dq,   u = 1 - p tan(ti),
    W = u * G / 1       with, for the V-groove (Eq. 12),  W = min(u, 2, X),
    X = 4u / (1 + p^2 + q^2) - 2 = 2 cos(theta_r) / cos(theta_i),

(Smith: W = u G1(ti) G1(tr); none: W = u).  The reflected ray is above the
horizon exactly on the disk (p + tan ti)^2 + q^2 < sec^2 ti, where X > 0; the
facet faces the source everywhere on that disk.  The integrand is smooth
except on three curves, where G switches branch: u = 2 (the line
p = -cot ti), X = 2 and X = u (conics, solved for q at each p).  We integrate
exactly up to the disk's edge (outer variable chi with p = pe - 2 sin^2(chi/2)/
cos ti, q_max = sin(chi)/cos ti, which removes the square-root edge behaviour
and every cancellation at grazing incidence), split at each kink, clip the
Gaussian at K = 8.5 standard deviations (tail < 1e-15) and use Gauss-Legendre
on each smooth piece.  The error estimate is the difference from a rule with
twice the nodes, doubled.

The table
---------
:func:`build_table` computes rho on a grid of x = 1 - sqrt(cos theta_i) in [0, 1]
and of ln(rms_slope) in [ln 1e-4, ln 100] (uniform in ln rms_slope, 20 nodes per
decade); :class:`DHRTable` interpolates it with bicubic splines.  x crowds the nodes towards
grazing incidence, where rho changes over a range of cos theta_i of the order of
rms_slope; rho is a smooth function of x at both ends.  The x nodes are uniform
(step 1/128) up to x = 15/16 and four times denser (step 1/512) above it: for a
near-mirror surface (rms_slope ~1e-4) the grazing dip of rho lies within
1 - x ~ sqrt(rms_slope) ~ 0.01 of the end, which the uniform step resolved only
to 7.5e-3 (measured); with the refined end the interpolation error is below
2e-4 over the whole table (``hyde_bsdf/validation/dhr_convergence.py`` charts it).

Shipped as data
---------------
The tables are package data, as Mitsuba ships its spectra: ``hyde_bsdf/data/dhr_table.npz``
holds rho and rho_avg of every shadowing term (float64, so that the evaluator's numbers do not
depend on how the table was obtained), and ``hyde_bsdf/data/dhr_texture_{vgroove,smith,none}.npz`` the
plugin's resampled 1 - rho texture (:class:`DHRTexture`, float32, the values the plugin's
``mi.Texture2f`` holds), so that loading a scene neither integrates, nor resamples, nor imports
SciPy.  ``tools/make_dhr_tables.py`` writes them (:func:`build_table`, :func:`texture_from_table`);
``tests/test_dhr_table.py`` recomputes a sample of nodes with the quadrature and of texels from
the table.  :func:`load_table` and :func:`load_texture` read them with :mod:`importlib.resources`,
once per process; nothing is built or written at load.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources

import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.model.checks import broadcast_named, check_bool, real_array
from hyde_bsdf.model.parameters import DHR_TABLE_RMS_SLOPE
from hyde_bsdf.model.terms import shadowing_term
from hyde_bsdf.progress import Throttle, as_callback

__all__ = ["dhr_specular_pec", "dhr_quadrature", "DHRTable", "DHRHemisphere", "DHRTexture", "load_table",
           "load_texture", "build_table", "texture_from_table", "x_of_theta", "theta_of_x", "table_x_nodes",
           "TABLE_THETA_POINTS", "TABLE_SLOPE_POINTS", "TABLE_SLOPE_RANGE", "TABLE_FILE", "TEXTURE_FILE"]

_K = 8.5                       # Gaussian clipped at K sigma: exp(-K^2/2) < 2e-16
_THETA_MAX = 0.5 * math.pi - 1e-9   # cos(theta) kept > 0; rho is continuous up to pi/2

#: x = 1 - sqrt(cos theta) nodes: step 1/TABLE_X_STEPS up to TABLE_X_REFINE_FROM, then
#: TABLE_X_REFINE times finer up to 1 (the grazing dip of near-mirror surfaces; module docstring)
TABLE_X_STEPS = 128
TABLE_X_REFINE_FROM = 15 / 16
TABLE_X_REFINE = 4
TABLE_THETA_POINTS = (round(TABLE_X_REFINE_FROM * TABLE_X_STEPS)          # 120 coarse nodes
                      + round((1 - TABLE_X_REFINE_FROM) * TABLE_X_STEPS * TABLE_X_REFINE) + 1)  # + 33 fine
TABLE_SLOPE_POINTS = 121       # 20 per decade over 6 decades
TABLE_SLOPE_RANGE = DHR_TABLE_RMS_SLOPE   # wider than the accepted RMS_SLOPE (parameters.py)
#: the plugin's texture of 1 - rho: nodes uniform in x on [0, 1], and per decade of rms_slope over
#: the table's whole range (its error and size: mitsuba/plugin.py's DOC, "DHR lookup")
TEXTURE_X_POINTS = 1025
TEXTURE_SLOPE_PER_DECADE = 192
#: the fine uniform x grid of :meth:`DHRTable.x_slice` (the diffuse terms interpolate it linearly)
X_SLICE_POINTS = 4097
#: up to this many angles :meth:`DHRHemisphere.one_minus` evaluates the spline at their nodes only
_FEW_ANGLES = 64
#: the shipped files in hyde_bsdf/data/ (written by tools/make_dhr_tables.py)
TABLE_FILE = "dhr_table.npz"
TEXTURE_FILE = "dhr_texture_{}.npz"


def _gauss_legendre(n):
    x, w = np.polynomial.legendre.leggauss(n)
    return x, w


def _chi_of_p(p, pe, cos_i):
    """Inverse of p(chi) = pe - 2 sin^2(chi/2)/cos_i, clipped to [0, pi]."""
    with np.errstate(invalid="ignore"):
        x = np.clip((pe - p) * cos_i * 0.5, 0.0, 1.0)
    return 2.0 * np.arcsin(np.sqrt(x))


def _dhr_batch(theta, slope, term, n_outer, n_inner):
    """rho for 1-D arrays theta, slope of equal length and a shadowing record (no validation)."""
    theta = np.minimum(theta, _THETA_MAX)
    ci, si = np.cos(theta), np.sin(theta)
    tan = si / ci
    pe = ci / (1.0 + si)                      # right edge of the disk, without cancellation
    win = _K * slope
    chi_a = _chi_of_p(np.minimum(win, pe), pe, ci)
    chi_b = _chi_of_p(np.maximum(-win, pe - 2.0 / ci), pe, ci)
    # Split points in p: the Gaussian's scale (a Gaussian over +-8.5 sigma needs
    # many nodes in one piece, few in pieces of 2.5 sigma) and where the shadowing's
    # integrand has kinks (the V-groove's: ShadowingTerm.dhr_kinks_p)
    splits = [c * slope for c in (-5.0, -2.5, 0.0, 2.5, 5.0)]
    if term.dhr_kinks_p is not None:
        splits += term.dhr_kinks_p(theta, ci, si, tan)
    chis = np.sort(np.stack([np.clip(_chi_of_p(k, pe, ci), chi_a, chi_b) for k in splits]), axis=0)
    outer_edges = [chi_a, *chis, chi_b]
    xo, wo = _gauss_legendre(n_outer)
    xi, wi = _gauss_legendre(n_inner)
    total = np.zeros_like(theta)
    b = (slice(None), None)                   # broadcast batch over nodes
    for lo, hi in zip(outer_edges[:-1], outer_edges[1:]):
        half = 0.5 * (hi - lo)
        chi = (0.5 * (hi + lo))[b] + half[b] * xo                  # (B, n_outer)
        s_half = np.sin(0.5 * chi)
        p = pe[b] - 2.0 * s_half * s_half / ci[b]
        sin_chi = np.sin(chi)
        jac = sin_chi / ci[b]                                      # |dp/dchi|
        q_top = np.minimum(sin_chi / ci[b], win[b])
        u = 1.0 - p * tan[b]
        q_splits = [np.minimum(c * slope[b], q_top) for c in (2.5, 5.0)]   # Gaussian scale
        if term.dhr_kinks_q is not None:
            q_splits += term.dhr_kinks_q(u, p, q_top)
        inner_edges = [np.zeros_like(q_top), *np.sort(np.stack(q_splits), axis=0), q_top]
        inner = np.zeros_like(p)
        for qlo, qhi in zip(inner_edges[:-1], inner_edges[1:]):
            qh = 0.5 * (qhi - qlo)
            q = (0.5 * (qhi + qlo))[..., None] + qh[..., None] * xi  # (B, n_outer, n_inner)
            r2 = p[..., None] ** 2 + q * q
            s2 = (slope * slope)[:, None, None]
            g = np.exp(-r2 / (2.0 * s2)) / (2.0 * math.pi * s2)
            W = term.dhr_weight(u[..., None], r2, ci[:, None, None], slope[:, None, None])
            inner += qh * np.einsum("bok,k->bo", g * W, wi)
        total += half * np.einsum("bo,o->b", 2.0 * inner * jac, wo)  # 2: q and -q
    return total


def dhr_quadrature(theta_i, rms_slope, shadowing="vgroove", n_outer=16, n_inner=10,
                   error_estimate=False, chunk=2048):
    """rho^{s,PEC}(theta_i; rms_slope) by the slope-space quadrature (module docstring).

    Parameters
    ----------
    theta_i : array_like of real numbers, radians in [0, pi/2]
    rms_slope : array_like, the paper's sqrt(2) sigma_h / l, in [1e-4, 100]; broadcast with theta_i
    shadowing : "vgroove" (paper Eq. 12) | "smith" | "none"
    n_outer, n_inner : Gauss-Legendre nodes per smooth piece
    error_estimate : also return 2 |rho(n) - rho(2n)|, an upper estimate of the error

    Returns rho (and the error estimate) with the broadcast shape.  A complex, string or
    boolean argument raises TypeError, a non-finite, out-of-range or non-broadcastable one
    ValueError, each naming the parameter.
    """
    term = shadowing_term(shadowing)
    t = real_array("theta_i", theta_i, "radians in [0, pi/2]")
    s = real_array("rms_slope", rms_slope, f"in [{TABLE_SLOPE_RANGE[0]:g}, {TABLE_SLOPE_RANGE[1]:g}]")
    broadcast_named(theta_i=t, rms_slope=s)
    t, s = np.broadcast_arrays(t, s)
    shape = t.shape
    t, s = t.ravel(), s.ravel()
    if np.any((t < 0) | (t > 0.5 * math.pi)):
        raise UsageError("theta_i must be in [0, pi/2] radians")
    lo, hi = TABLE_SLOPE_RANGE[0] * (1 - 1e-12), TABLE_SLOPE_RANGE[1] * (1 + 1e-12)  # exp(log(100))
    if np.any((s < lo) | (s > hi)):
        # the evaluator's range; far below it the clipped Gaussian misses the disk (rho -> 0
        # instead of 1 at rms_slope 1e-30), far above it g underflows and overflows
        raise UsageError(f"rms_slope must be in [{TABLE_SLOPE_RANGE[0]:g}, {TABLE_SLOPE_RANGE[1]:g}]")
    for name, v in (("n_outer", n_outer), ("n_inner", n_inner)):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or not 1 <= v <= 512:
            raise UsageError(f"{name} must be an integer in [1, 512], got {v!r}")
    check_bool("error_estimate", error_estimate)
    rho = np.empty_like(t)
    err = np.empty_like(t) if error_estimate else None
    step = max(1, chunk * 48 * 24 // (n_outer * n_inner))
    for i in range(0, t.size, step):
        sl = slice(i, i + step)
        rho[sl] = _dhr_batch(t[sl], s[sl], term, n_outer, n_inner)
        if error_estimate:
            # twice the change under node doubling: a safe bound for exponential convergence
            err[sl] = 2.0 * np.abs(rho[sl] - _dhr_batch(t[sl], s[sl], term, 2 * n_outer, 2 * n_inner))
    rho = rho.reshape(shape)
    return (rho, err.reshape(shape)) if error_estimate else rho


# --------------------------------------------------------------------------- table

@dataclass
class DHRTable:
    """rho^{s,PEC} on a uniform (x, ln rms_slope) grid, x = 1 - sqrt(cos theta), bicubic.

    Attributes: ``x`` (increasing on [0, 1], :func:`table_x_nodes`: not uniform), ``theta`` = arccos((1 - x)^2) (radians,
    the same nodes), ``log_slope`` (uniform in ln rms_slope),
    ``rho[len(x), len(log_slope)]``, ``rho_avg[len(log_slope)]``
    = 2 int_0^{pi/2} rho cos(t) sin(t) dt (the albedo average the reciprocal diffuse
    variant needs), ``shadowing`` and ``build_seconds``.
    """
    x: np.ndarray
    theta: np.ndarray
    log_slope: np.ndarray
    rho: np.ndarray
    rho_avg: np.ndarray
    shadowing: str
    build_seconds: float = float("nan")
    _spline: object = field(default=None, repr=False, compare=False)

    def spline(self):
        if self._spline is None:
            from scipy.interpolate import RectBivariateSpline
            self._spline = RectBivariateSpline(self.x, self.log_slope, self.rho, kx=3, ky=3)
        return self._spline

    def __call__(self, theta_i, rms_slope):
        """Interpolated rho at (theta_i, rms_slope), broadcast; slopes clamped to the table."""
        t, s = np.broadcast_arrays(np.asarray(theta_i, float), np.asarray(rms_slope, float))
        ls = np.clip(np.log(s), self.log_slope[0], self.log_slope[-1])
        return np.clip(self.spline().ev(x_of_theta(t), ls), 0.0, None).reshape(t.shape)

    def on_grid(self, x, log_slope):
        """rho on the tensor grid x[:, None] x log_slope[None, :] (x = 1 - sqrt(cos theta)).

        The same bicubic spline as ``__call__``, evaluated as a tensor product: several times
        faster than ``__call__`` on a meshgrid (used to resample the table into textures).
        """
        ls = np.clip(np.asarray(log_slope, float), self.log_slope[0], self.log_slope[-1])
        return np.clip(self.spline()(np.clip(np.asarray(x, float), 0.0, 1.0), ls, grid=True), 0.0, None)

    def average(self, rms_slope):
        """rho_avg at rms_slope (cubic in ln rms_slope)."""
        from scipy.interpolate import CubicSpline
        ls = np.clip(np.log(np.asarray(rms_slope, float)), self.log_slope[0], self.log_slope[-1])
        return CubicSpline(self.log_slope, self.rho_avg)(ls)

    @lru_cache(maxsize=64)
    def x_slice(self, rms_slope: float, points: int = X_SLICE_POINTS):
        """rho at one rms_slope on a fine uniform grid of x, for np.interp in x.

        Evaluated as a tensor product (one column): the same spline values as ``ev`` at each point,
        bit for bit, in a third of the time (a fit's finite differences miss this cache often)."""
        return self.x_nodes(rms_slope, slice(None), points)

    def x_nodes(self, rms_slope: float, nodes, points: int = X_SLICE_POINTS):
        """(x, rho) of :meth:`x_slice` at the nodes ``nodes`` (an increasing index array, or a slice) only.

        The spline is evaluated at each x on its own (its basis at that x, the coefficients of its
        interval), so these are the slice's values bit for bit, at the cost of the nodes asked for."""
        grid = _fine_grid(points)[nodes]
        ls = np.clip(math.log(rms_slope), self.log_slope[0], self.log_slope[-1])
        return grid, np.clip(self.spline()(grid, np.array([ls]), grid=True)[:, 0], 0.0, None)

    def __hash__(self):
        return id(self)


class DHRHemisphere:
    """The specular DHR of a PEC on the 2-D surface at one ``rms_slope``, read from the table: the
    hemisphere the diffuse terms of :mod:`hyde_bsdf.model.diffuse` are written on.

    ``one_minus(theta)`` = 1 - rho(theta) (linear in x on the table's fine slice: :meth:`DHRTable.x_slice`),
    ``measure`` = int cos dw = pi, ``one_minus_avg`` = 1 - rho_avg = int_0^1 4 (1-x)^3 (1 - rho(x)) dx
    from the very samples ``one_minus`` interpolates (1 - rho clipped at 0), so that a term's
    hemispherical integral is exactly 1 - rho(theta_i).  The table is read on first use.
    """
    measure = math.pi

    def __init__(self, shadowing, rms_slope):
        self.shadowing, self.rms_slope = shadowing, float(rms_slope)
        self._samples = None

    def _slice(self):
        if self._samples is None:
            grid, rho_x = load_table(self.shadowing).x_slice(self.rms_slope)
            self._samples = grid, 1.0 - rho_x
        return self._samples

    def one_minus(self, theta):
        x = x_of_theta(theta)
        if self._samples is None and np.size(x) <= _FEW_ANGLES:
            # the slice's two nodes around each x only (a fit's few geometries at a new rms_slope):
            # np.interp reads no other node, so the result is the full slice's bit for bit
            below = np.searchsorted(_fine_grid(X_SLICE_POINTS), np.ravel(x), side="right") - 1
            nodes = np.unique(np.clip(np.concatenate([below, below + 1]), 0, X_SLICE_POINTS - 1))
            grid, rho_x = load_table(self.shadowing).x_nodes(self.rms_slope, nodes)
            return np.interp(x, grid, 1.0 - rho_x)
        grid, one_minus_x = self._slice()
        return np.interp(x, grid, one_minus_x)

    @property
    def one_minus_avg(self) -> float:
        grid, one_minus_x = self._slice()
        return float(np.trapezoid(4.0 * (1.0 - grid) ** 3 * np.maximum(one_minus_x, 0.0), grid))


@lru_cache(maxsize=4)
def _fine_grid(points: int) -> np.ndarray:
    grid = np.linspace(0.0, 1.0, points)
    grid.flags.writeable = False
    return grid


def x_of_theta(theta):
    """Table coordinate x = 1 - sqrt(cos theta) (theta clipped to [0, pi/2])."""
    return 1.0 - np.sqrt(np.cos(np.clip(theta, 0.0, 0.5 * math.pi)).clip(0.0, 1.0))


def theta_of_x(x):
    """Inverse of :func:`x_of_theta`: theta = arccos((1 - x)^2)."""
    return np.arccos((1.0 - np.asarray(x, float)) ** 2)


def table_x_nodes():
    """The table's x nodes: uniform steps of 1/128 to 15/16, then steps of 1/512 to 1."""
    coarse = np.arange(round(TABLE_X_REFINE_FROM * TABLE_X_STEPS)) / TABLE_X_STEPS
    fine_steps = TABLE_X_STEPS * TABLE_X_REFINE
    start = round(TABLE_X_REFINE_FROM * fine_steps)
    fine = np.arange(start, fine_steps + 1) / fine_steps
    return np.concatenate([coarse, fine])


def _grid():
    x = table_x_nodes()
    log_slope = np.linspace(math.log(TABLE_SLOPE_RANGE[0]), math.log(TABLE_SLOPE_RANGE[1]), TABLE_SLOPE_POINTS)
    return x, log_slope


def _rho_average(x, rho):
    """rho_avg = 2 int rho cos(t) sin(t) dt = int_0^1 rho d(cos^2 t), by Simpson's rule in x.

    With c = cos t = (1 - x)^2: d(c^2) = -4 (1 - x)^3 dx, so rho_avg = int_0^1 4 (1-x)^3 rho dx.
    """
    from scipy.integrate import simpson
    return simpson(rho * (4.0 * (1.0 - x) ** 3)[:, None], x=x, axis=0)


def build_table(shadowing="vgroove", progress=True) -> DHRTable:
    """Compute the table by quadrature (tools/make_dhr_tables.py ships it; load_table reads it).
    About 2-4 s on 2 cores.

    ``progress``: a callback ``progress(message)`` told every few seconds; True for lines on
    stderr unless the command line's ``-q`` silenced them (:mod:`hyde_bsdf.progress`).
    """
    t0 = time.perf_counter()
    x, log_slope = _grid()
    theta = theta_of_x(x)
    T, L = np.meshgrid(theta, log_slope, indexing="ij")
    rho = np.empty(T.size)
    flat_t, flat_s = T.ravel(), np.exp(L.ravel())
    step = 1024
    report = Throttle(as_callback(progress), 1.0)
    for i in range(0, flat_t.size, step):
        rho[i:i + step] = dhr_quadrature(flat_t[i:i + step], flat_s[i:i + step], shadowing,
                                         *shadowing_term(shadowing).dhr_order)
        report(lambda: f"building DHR table ({shadowing}): {min(i + step, flat_t.size)}/{flat_t.size}")
    rho = rho.reshape(T.shape)
    return DHRTable(x, theta, log_slope, rho, _rho_average(x, rho), shadowing,
                    time.perf_counter() - t0)


@dataclass(frozen=True)
class DHRTexture:
    """The plugin's 1 - rho^{s,PEC}: ``one_minus[TEXTURE_X_POINTS, ns]`` (float32) on nodes uniform in
    x = 1 - sqrt(cos theta) over [0, 1] and in ln(rms_slope) over [``log_lo``, ``log_hi``] (the table's
    range, ``ns`` = TEXTURE_SLOPE_PER_DECADE per decade + 1), and ``one_minus_avg[ns]`` = 1 - rho_avg
    (float32) on the same slope nodes.  Stored as 1 - rho so that the small diffuse weights of smooth
    surfaces keep their float32 relative precision."""
    log_lo: float
    log_hi: float
    one_minus: np.ndarray
    one_minus_avg: np.ndarray


def texture_from_table(table: DHRTable, x_points: int = TEXTURE_X_POINTS,
                       per_decade: int = TEXTURE_SLOPE_PER_DECADE) -> DHRTexture:
    """Resample ``table`` through its own bicubic spline (:meth:`DHRTable.on_grid`) and its cubic
    rho_avg (:meth:`DHRTable.average`) onto the texture's grid (SciPy; tools/make_dhr_tables.py)."""
    lo, hi = float(table.log_slope[0]), float(table.log_slope[-1])
    ns = int(round((hi - lo) / math.log(10.0) * per_decade)) + 1
    ls = np.linspace(lo, hi, ns)
    one_minus = 1.0 - table.on_grid(np.linspace(0.0, 1.0, x_points), ls)
    one_minus_avg = 1.0 - np.asarray(table.average(np.exp(ls)), dtype=float)
    return DHRTexture(lo, hi, one_minus.astype(np.float32), one_minus_avg.astype(np.float32))


def _data_file(name: str):
    """A shipped file of ``hyde_bsdf/data/``, opened for reading (importlib.resources)."""
    return resources.files("hyde_bsdf").joinpath("data", name).open("rb")


def _not_shipped(what: str, name: str):
    return LookupError(f"the DHR {what} of shadowing={name!r} is not shipped in hyde_bsdf/data/: run "
                       f"tools/make_dhr_tables.py (a new shadowing record needs its table)")


_TABLES: dict[str, DHRTable] = {}
_TEXTURES: dict[str, DHRTexture] = {}


def load_table(shadowing="vgroove") -> DHRTable:
    """The shipped DHR table of a shadowing term (``hyde_bsdf/data/dhr_table.npz``), read once per
    process; LookupError naming the script to run if the term has none."""
    name = shadowing_term(shadowing).name
    if name not in _TABLES:
        with _data_file(TABLE_FILE) as fh, np.load(fh, allow_pickle=False) as z:
            if f"{name}_rho" not in z.files:
                raise _not_shipped("table", name)
            x, log_slope, rho, rho_avg = z["x"], z["log_slope"], z[f"{name}_rho"], z[f"{name}_rho_avg"]
        _TABLES[name] = DHRTable(x, theta_of_x(x), log_slope, rho, rho_avg, name)
    return _TABLES[name]


def encode_texture_values(a: np.ndarray) -> np.ndarray:
    """float32 values as second differences along axis 0 of their bit patterns (uint32, modulo 2^32):
    exact, and a smooth table's differences compress 2x better than its values."""
    u = np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)
    d = np.diff(u, axis=0, prepend=np.uint32(0))
    return np.diff(d, axis=0, prepend=np.uint32(0))


def decode_texture_values(d2: np.ndarray) -> np.ndarray:
    """The inverse of :func:`encode_texture_values`, in place: two running sums modulo 2^32."""
    u = np.asarray(d2, dtype=np.uint32)
    np.cumsum(u, axis=0, out=u)
    np.cumsum(u, axis=0, out=u)
    return u.view(np.float32)


def load_texture(shadowing="vgroove") -> DHRTexture:
    """The plugin's shipped 1 - rho texture of a shadowing term
    (``hyde_bsdf/data/dhr_texture_{vgroove,smith,none}.npz``), read once per process: no quadrature,
    no resampling, no SciPy."""
    name = shadowing_term(shadowing).name
    if name not in _TEXTURES:
        try:
            fh = _data_file(TEXTURE_FILE.format(name))
        except FileNotFoundError:
            raise _not_shipped("texture", name) from None
        with fh, np.load(fh, allow_pickle=False) as z:
            lo, hi = (float(v) for v in z["log_range"])
            _TEXTURES[name] = DHRTexture(lo, hi, decode_texture_values(z["one_minus_d2"]), z["one_minus_avg"])
    return _TEXTURES[name]


def dhr_specular_pec(theta_i, rms_slope, shadowing="vgroove", error_estimate=False):
    """rho^{s,PEC}(theta_i; rms_slope), paper Eqs. 14-16: the fraction of the light
    a rough perfect conductor returns in its specular (single-reflection) lobe.

    Computed by quadrature in slope space (module docstring), accurate to better
    than 1e-4 absolute for theta_i in [0, 89.9] deg and rms_slope in [0.01, 3]
    (tests check it).  ``theta_i`` in radians; ``rms_slope`` = sqrt(2) sigma_h / l.
    With ``error_estimate=True`` returns (rho, estimated absolute error).
    """
    return dhr_quadrature(theta_i, rms_slope, shadowing, error_estimate=error_estimate)
