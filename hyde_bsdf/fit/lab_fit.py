"""One model fitted jointly to lab Mueller data at every wavelength (:func:`fit_model`).

    minimize  chi^2 = sum over wavelengths g, rows m:  ((F_00 - M_00) / sigma_00)^2              (M00, 1/sr)
                                                      + sum_jk ((F_jk / F_00 - M_jk) / sigma_jk)^2  (normalized)

over one ``rms_slope`` shared by the wavelengths, ``n`` and ``k`` per wavelength (the paper's
eta = n - jk) and, for the Lambertian diffuse term, its albedo ``diffuse_reflectance`` (shared by
the wavelengths or one per wavelength), any subset held fixed.  F is paper Eq. 17 with the
chosen shadowing and diffuse terms, evaluated through
:class:`hyde_bsdf.model.prepared.PreparedGeometry` (the evaluator's functions, the angles computed
once).  The CSV's data (:mod:`hyde_bsdf.fit.lab_data`): M00 when measured, every normalized
element given.

Start: a grid over rms_slope x (n, k) per wavelength x albedo, evaluated at once (the albedo in
closed form from M00 when it is measured), then a bounded trust-region least-squares fit
(``scipy.optimize.least_squares``) with a Jacobian by forward differences per parameter
(each n_g, k_g moves only its wavelength's rows; the albedo's column is analytic).  Without
sigmas the noise is estimated from a first fit (relative for M00, absolute for the normalized
elements) and the fit repeated with it.

Uncertainty and verdict as :func:`hyde_bsdf.fit.fit_mueller`'s: the linearized covariance, the
Birge ratio where chi^2 is far above its dof, the chi^2 verdict (the data's floor without
sigmas), robust errors where the misfit is systematic.  A misfit is never blamed on the sigmas
while a parameter is held fixed: the fit is then repeated with every parameter free, and if that
removes the misfit the verdict names the fixed parameter (:func:`blame_fixed`).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.fit.adequacy import (Verdict, birge_scaling, blame_fixed_parameters, chi2_sf, chi2_verdict,
                                    cluster_covariance, correlation, floor_verdict, geometry_clusters, half_angles,
                                    larger_errors)
from hyde_bsdf.fit.lab_data import LabData
from hyde_bsdf.io.measurements import M00, element_index
from hyde_bsdf.model.parameters import DIFFUSE_REFLECTANCE, FIT_PARAMETERS, NATURAL_INDEX, RMS_SLOPE
from hyde_bsdf.model.terms import diffuse_term

__all__ = ["PARAMETERS", "LabModel", "ModelFit", "fit_model", "blame_fixed", "param_name", "check_enough"]

#: the fit's parameter names, in this order everywhere (the registry's FIT_PARAMETERS, then the
#: Lambertian albedo in the plugin's and the evaluator's spelling)
PARAMETERS = FIT_PARAMETERS + ("diffuse_reflectance",)
BOUNDS = {"rms_slope": RMS_SLOPE.bounds, "n": NATURAL_INDEX.bounds, "k": NATURAL_INDEX.bounds,
          "diffuse_reflectance": DIFFUSE_REFLECTANCE.bounds}
#: the start grid: rms_slope, n, k, and the albedo (without M00, where it has no closed form)
GRID_SLOPES = tuple(np.geomspace(0.02, 1.5, 12))
GRID_N = (0.15, 0.4, 0.8, 1.3, 1.8, 2.6, 4.0)
GRID_K = (0.0, 0.5, 1.5, 3.0, 5.5, 9.0, 14.0)
GRID_ALBEDO = (0.0, 0.01, 0.03, 0.1, 0.3)
#: the finest albedo step the normalized elements' derivative resolves: where F00 underflows far from
#: the lobe, d(F_jk/F00)/d albedo = -(F_jk/F00) u / F00 is unbounded (the ratio falls from its specular
#: value to 0 within an albedo of F00 / u); the chord over this step keeps the Jacobian finite
ALBEDO_STEP = 1e-9
#: noise assumed for the start and the first pass of a fit without sigmas
START_NOISE = {"m00_relative": 0.05, "elements": 0.02}


@dataclass(frozen=True)
class LabModel:
    """A candidate: shadowing and diffuse term names; ``albedo`` "shared" or "per_wavelength" (the
    Lambertian term's albedo; ignored otherwise); ``dielectric``: k held at 0 at every wavelength."""

    shadowing: str
    diffuse: str
    albedo: str = "shared"
    dielectric: bool = False

    @property
    def lambertian(self) -> bool:
        """Whether the diffuse term has a free albedo (the ``lambertian`` record's own parameter)."""
        return "diffuse_reflectance" in diffuse_term(self.diffuse).parameters

    @property
    def label(self) -> str:
        extra = " per wavelength" if self.lambertian and self.albedo == "per_wavelength" else ""
        return f"{self.shadowing}/{self.diffuse}{extra}" + (" k=0" if self.dielectric else "")


def _keys(model: LabModel, groups: int) -> list:
    """Every parameter of ``model`` as (name, group or None), in :data:`PARAMETERS` order."""
    keys = [(q, g) for g in range(groups) for q in ("n", "k")] + [("rms_slope", None)]
    if model.lambertian:
        keys += ([("diffuse_reflectance", g) for g in range(groups)] if model.albedo == "per_wavelength"
                 else [("diffuse_reflectance", None)])
    return keys


class _Problem:
    """Weighted residuals of ``model`` over the free parameters (the others held at ``values``)."""

    def __init__(self, data: LabData, model: LabModel, free: list, values: dict, tick=None):
        self.data, self.model, self.free, self.values = data, model, list(free), dict(values)
        self.tick = tick
        idx = [element_index(c) for c in data.elements]
        self.rows_, self.cols_ = [a for a, _ in idx], [b for _, b in idx]
        self._lobes, self._units = {}, {}
        # the Lambertian term per unit albedo (model/terms.py's record): F00 is linear in the albedo
        self.per_albedo = [g.geometry.per_albedo(model.diffuse) for g in data.groups]
        self.lo = np.array([BOUNDS[q][0] for q, _ in self.free])
        self.hi = np.array([BOUNDS[q][1] for q, _ in self.free])

    def unpack(self, x) -> dict:
        v = dict(self.values)
        v.update(zip(self.free, (float(a) for a in x)))
        return v

    def param(self, v, name, g):
        return v[(name, g)] if (name, g) in v else v[(name, None)]

    def _factors(self, g, s, n, k):
        """(lobe, diffuse factor) at roughness s and (U_00, the measured elements of U) at n, k: cached."""
        geo, m = self.data.groups[g].geometry, self.model
        key = (g, s)
        if key not in self._lobes:
            if len(self._lobes) > 16:
                self._lobes.clear()
            self._lobes[key] = (geo.lobe(s, m.shadowing), geo.diffuse(s, m.diffuse, m.shadowing))
        key = (g, n, k)
        if key not in self._units:
            if len(self._units) > 32:
                self._units.clear()
            U = geo.unit_mueller(n, k) if math.hypot(n, k) >= 1e-6 else geo.unit_mueller(1e-6, 0.0)
            self._units[key] = (U[0, 0], U[self.rows_, self.cols_])
        return self._lobes[(g, s)], self._units[key]

    def predict_group(self, v, g):
        """(F00, the elements (E, N): absolute with M00 data, normalized without) of group ``g`` at the
        parameter values ``v``."""
        s, n, k = v[("rms_slope", None)], v[("n", g)], v[("k", g)]
        (L, d), (U00, Ue) = self._factors(g, s, n, k)
        F00 = (L + d) * U00
        if self.model.lambertian:
            F00 = F00 + self.param(v, "diffuse_reflectance", g) * self.per_albedo[g]
        if self.data.absolute:
            return F00, Ue * L
        # L / F00 <= 1 / U00 stays finite where both underflow (far from a lobe without a diffuse term)
        ratio = np.divide(L, F00, out=np.zeros_like(F00), where=F00 > 0.0)
        return F00, Ue * ratio

    def _stack(self, g, F00, norm):
        return np.concatenate(([F00] if self.data.has_m00 else []) + list(norm))

    def prediction(self, v) -> np.ndarray:
        """The model's values in the order of ``data.y``."""
        out = np.empty(self.data.y.size)
        for g in range(len(self.data.groups)):
            out[self.data.rows[g]] = self._stack(g, *self.predict_group(v, g))
        return out

    def __call__(self, x) -> np.ndarray:
        r = self.data.whiten(self.prediction(self.unpack(x)) - self.data.y)
        if self.tick is not None:
            self.tick(r)
        return r

    def jac(self, x) -> np.ndarray:
        """Forward differences, group by group (a group's index moves only its rows); the
        albedo's column analytic: dF00/da = u (the term per unit albedo, 1/pi), d(F_jk/F00)/da =
        -(F_jk/F00) u / F00 (F00 floored at ALBEDO_STEP u: finite where the lobe underflows)."""
        v0 = self.unpack(x)
        J = np.zeros((self.data.y.size, len(self.free)))
        for g in range(len(self.data.groups)):
            rows = self.data.rows[g]
            F00, norm = self.predict_group(v0, g)
            base = self._stack(g, F00, norm)
            for col, (q, gq) in enumerate(self.free):
                if gq is not None and gq != g:
                    continue
                if q == "diffuse_reflectance":
                    dn = np.zeros_like(norm)          # absolute elements do not depend on it
                    if not self.data.absolute:        # the chord over albedo steps of ALBEDO_STEP at least
                        u = self.per_albedo[g]
                        dn = -norm * u / np.maximum(F00, ALBEDO_STEP * u)
                    J[rows, col] = self._stack(g, self.per_albedo[g], dn)
                    continue
                h = 1e-7 * max(1.0, abs(v0[(q, gq)]))
                h = -h if v0[(q, gq)] + h > self.hi[col] else h
                v = dict(v0)
                v[(q, gq)] += h
                J[rows, col] = (self._stack(g, *self.predict_group(v, g)) - base) / h
        return self.data.whiten(J)


def _grid_start(data: LabData, model: LabModel, values: dict, free: list) -> dict:
    """Start values from grids (module docstring), in three cheap passes instead of one product
    grid: the index per wavelength over (n, k) at a middle roughness, then the roughness with that
    index, then the index again at that roughness (the albedo chosen at every point)."""
    grid = lambda key, values_: values_ if key in free and key not in values else (values[key],)
    slopes = grid(("rms_slope", None), GRID_SLOPES)
    w = data.w if data.w is not None else _start_noise(data)
    combos, units = [], []
    for g, group in enumerate(data.groups):
        ns = grid(("n", g), GRID_N)
        ks = (0.0,) if model.dielectric else grid(("k", g), GRID_K)
        combos.append([(n, k) for n in ns for k in ks])
        units.append(np.stack([group.geometry.unit_mueller(max(n, 1e-6), k) for n, k in combos[-1]]))
    s = slopes[len(slopes) // 2]
    for scan in ("index", "slope", "index"):
        trial = (s,) if scan == "index" else slopes
        costs, picks = zip(*(_group_grid(data, model, g, U if scan == "index" else U[best[g]:best[g] + 1],
                                         trial, w, values, free) for g, U in enumerate(units)))
        if scan == "index":
            best = [int(np.argmin(c[0])) for c in costs]
            albedos = [float(p[0, j]) for p, j in zip(picks, best)]
        else:
            i = int(np.argmin(sum(c[:, 0] for c in costs)))
            s = trial[i]
    start = dict(values)
    start[("rms_slope", None)] = float(s)
    for g, j in enumerate(best):
        start[("n", g)], start[("k", g)] = combos[g][j]
        if ("diffuse_reflectance", g) in free:
            start[("diffuse_reflectance", g)] = albedos[g]
    if ("diffuse_reflectance", None) in free:
        start[("diffuse_reflectance", None)] = float(np.mean(albedos))
    return start


def _group_grid(data, model, g, U, slopes, w, values, free):
    """Costs (slopes, combos) of group ``g`` on a grid (U: the unit Mueller matrices of the
    (n, k) combos) and the albedo chosen at each point."""
    geo = data.groups[g].geometry
    y = data.y[data.rows[g]].reshape(len(data.columns), -1)
    wg = np.broadcast_to(w, data.y.shape)[data.rows[g]].reshape(len(data.columns), -1)
    off = int(data.has_m00)
    idx = [element_index(c) for c in data.elements]
    Ue = U[:, [a for a, _ in idx], [b for _, b in idx]] if idx else None        # (combos, E, N)
    fixed_a = values.get(("diffuse_reflectance", g), values.get(("diffuse_reflectance", None)))
    a_free = model.lambertian and any(key in free and key not in values for key in
                                      (("diffuse_reflectance", g), ("diffuse_reflectance", None)))
    unit = geo.per_albedo(model.diffuse)                                   # 1/pi: F00 is linear in the albedo
    costs = np.empty((len(slopes), U.shape[0]))
    picks = np.zeros((len(slopes), U.shape[0]))
    for i, s in enumerate(slopes):
        L, d = geo.lobe(s, model.shadowing), geo.diffuse(s, model.diffuse, model.shadowing)
        spec00 = (L + d) * U[:, 0, 0]                                    # (combos, N)
        if not model.lambertian:
            albedo = np.zeros((U.shape[0], 1))
        elif not a_free:
            albedo = np.full((U.shape[0], 1), fixed_a)
        elif data.has_m00:     # closed form: the weighted mean of the M00 excess over the specular part
            wt = 1.0 / wg[0] ** 2
            albedo = np.clip(((y[0] - spec00) * wt * unit).sum(-1) / (wt * unit * unit).sum(), 0.0, 1.0)[:, None]
        else:
            albedo = np.broadcast_to(np.array(GRID_ALBEDO), (U.shape[0], len(GRID_ALBEDO)))
        F00 = spec00[:, None, :] + albedo[..., None] * unit                # (combos, albedos, N)
        cost = (((F00 - y[0]) / wg[0]) ** 2).sum(-1) if data.has_m00 else np.zeros(albedo.shape)
        if idx and data.absolute:        # the albedo adds to M00 only
            cost = cost + (((L * Ue - y[off:]) / wg[off:]) ** 2).sum(axis=(-2, -1))[:, None]
        elif idx:
            inv = np.where(F00 > 0.0, 1.0 / np.maximum(F00, 1e-300), 0.0)   # elements 0 where F00 underflows
            with np.errstate(over="ignore", invalid="ignore"):
                norm = np.nan_to_num((L * Ue)[:, None] * inv[:, :, None, :], nan=0.0, posinf=1e3, neginf=-1e3)
            cost = cost + (((norm - y[off:]) / wg[off:]) ** 2).sum(axis=(-2, -1))
        j = np.argmin(cost, axis=1)
        costs[i] = cost[np.arange(cost.shape[0]), j]
        picks[i] = albedo[np.arange(cost.shape[0]), j]
    return costs, picks


def _start_noise(data: LabData) -> np.ndarray:
    """Standard deviations assumed where the data give none (the start, and a first pass)."""
    N = data.geometries
    parts = []
    for c in data.columns:
        if c == M00 or data.absolute:       # noise that scales with M00 (absolute elements too)
            y00 = np.abs(data.y[:N])
            parts.append(START_NOISE["m00_relative"] * y00 + 1e-3 * y00.max())
        else:
            parts.append(np.full(N, START_NOISE["elements"]))
    return np.concatenate(parts)


@dataclass
class ModelFit:
    """One model's joint fit.  Parameter keys are (name, group): group None for the shared ones
    (rms_slope, a shared albedo), else the index of the wavelength in ``data.groups``."""

    model: LabModel
    data: LabData
    values: dict
    free: list
    stderr: dict
    covariance: np.ndarray
    chi2: float
    dof: int
    residuals: np.ndarray
    success: bool
    message: str
    nfev: int
    verdict: Verdict
    fixed_by_user: tuple = ()
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    stderr_scale: float = 1.0

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def p_value(self) -> float:
        return float(chi2_sf(self.chi2, self.dof)) if self.dof > 0 else float("nan")

    @property
    def correlation(self) -> np.ndarray:
        return correlation(self.covariance) if np.all(np.isfinite(self.covariance)) else \
            np.where(np.eye(len(self.free), dtype=bool), 1.0, np.nan)

    def name(self, key) -> str:
        return param_name(self.data, key)

    def prediction(self) -> np.ndarray:
        """The fitted model's values in the order of ``data.y``."""
        return _Problem(self.data, self.model, self.free, self.values).prediction(self.values)

    def params(self, g: int) -> dict:
        """rms_slope, n, k (and diffuse_reflectance) at wavelength group ``g``, for :func:`hyde_bsdf.pbrdf`."""
        v = self.values
        out = {"rms_slope": v[("rms_slope", None)], "n": v[("n", g)], "k": v[("k", g)]}
        if self.model.lambertian:
            out["diffuse_reflectance"] = v.get(("diffuse_reflectance", g), v.get(("diffuse_reflectance", None)))
        return out


def param_name(data: LabData, key) -> str:
    """A parameter's name with its wavelength: ``rms_slope``, ``n@632.8nm``, ``n`` (no wavelength)."""
    q, g = key
    if g is None:
        return q
    wl = data.groups[g].wavelength
    return q if wl is None else f"{q}@{wl:g}nm"


def _determined(data: LabData, model: LabModel, names: tuple) -> tuple:
    """The requested parameter names the data can determine, and notes on those they cannot."""
    notes = []
    names = tuple(q for q in names if q != "diffuse_reflectance" or model.lambertian)
    if "rms_slope" in names and not data.has_m00 and model.diffuse == "none":
        names = tuple(q for q in names if q != "rms_slope")
        notes.append("rms_slope is not identified: without M00 and without a diffuse term the normalized "
                     "elements do not depend on it (the specular lobe's size cancels in M_jk/M_00); it is held "
                     "at its start value -- measure M00 (1/sr) to determine it")
    if not data.elements and ("n" in names or "k" in names):
        notes.append("n and k are seen only through the Fresnel reflectance in M00 (no normalized element "
                     "measured): expect large, correlated errors")
    return names, notes


@dataclass
class _Solution:
    x: np.ndarray
    fun: np.ndarray
    jac: np.ndarray
    nfev: int
    success: bool
    message: str


def _solve(problem: _Problem, x0, max_nfev, tol=1e-10) -> _Solution:
    """Bounded Levenberg-Marquardt on the normal equations, Marquardt's scaling diag(J^T J).

    A few parameters and thousands of residuals: each step solves a p x p system (scipy's
    trust-region solvers take an SVD of the whole Jacobian per step, which a loaded machine's
    threaded BLAS makes 30x slower than the model itself).  A parameter on a bound whose gradient
    points outwards is held there for the step; other steps are clipped to the box."""
    lo, hi = problem.lo, problem.hi
    x = np.clip(np.asarray(x0, float), lo, hi)
    r = problem(x)
    cost, nfev, lam = float(r @ r), 1, 1e-3
    J = problem.jac(x)
    for _ in range(max_nfev):
        g, H = J.T @ r, J.T @ J
        free = ~(((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0)))
        if not free.any():
            return _Solution(x, r, J, nfev, True, "every parameter on a bound")
        D = np.maximum(np.diag(H), 1e-300)
        accepted = False
        while lam < 1e16 and nfev < max_nfev:
            A = H[np.ix_(free, free)] + lam * np.diag(D[free])
            step = np.zeros_like(x)
            try:
                step[free] = np.linalg.solve(A, -g[free])
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            x_new = np.clip(x + step, lo, hi)
            r_new = problem(x_new)
            nfev += 1
            cost_new = float(r_new @ r_new)
            if np.isfinite(cost_new) and cost_new <= cost:
                accepted = True
                break
            lam *= 4.0
        if not accepted:
            return _Solution(x, r, J, nfev, lam >= 1e16, "no step lowers chi^2 further" if lam >= 1e16
                             else "the evaluation budget is spent")
        small_step = np.all(np.abs(x_new - x) <= tol * (np.abs(x) + tol))
        small_gain = cost - cost_new <= tol * max(cost, 1e-300)
        x, r, cost, lam = x_new, r_new, cost_new, max(lam / 3.0, 1e-12)
        J = problem.jac(x)
        if small_step or small_gain:
            return _Solution(x, r, J, nfev, True, "converged")
    return _Solution(x, r, J, nfev, False, "the evaluation budget is spent")


def fit_model(data: LabData, model: LabModel, *, fit=PARAMETERS, values: dict | None = None,
              start: dict | None = None, tick=None) -> ModelFit:
    """Fit ``model`` to ``data`` (module docstring).

    ``fit``: the parameter names to fit (of :data:`PARAMETERS`); the others are held at
    ``values`` (a dict key -> value for every parameter not fitted; keys as in :class:`ModelFit`).
    ``start``: start values (a previous fit's ``values``, e.g. a neighbouring model's), else the
    grid.  ``tick``: called with each residual vector (progress).
    """
    groups = len(data.groups)
    names, notes = _determined(data, model, tuple(fit))
    keys = _keys(model, groups)
    values = {key: v for key, v in (values or {}).items() if key in keys}
    if "rms_slope" not in names:
        values.setdefault(("rms_slope", None), 0.3)
    if model.dielectric:
        values.update({("k", g): 0.0 for g in range(groups)})
    free = [key for key in keys if key[0] in names and not (model.dielectric and key[0] == "k")]
    missing = [key for key in keys if key not in free and key not in values]
    if missing:
        raise UsageError(f"a value is needed for {', '.join(q for q, _ in missing)} when it is not fitted")
    if not free:
        raise UsageError("nothing to fit: every parameter is held fixed")
    user_fixed = tuple(sorted({q for q, _ in keys if q not in fit and not (model.dielectric and q == "k")}))
    init = _grid_start(data, model, values, free) if start is None else {**values, **{
        key: start[key] for key in free if key in start}}
    check_enough(data, free)
    if data.w is None:       # a first pass with assumed noise, then the noise from its residuals
        first = _Problem(data.with_noise(_start_noise(data)), model, free, values, tick)
        res = _solve(first, [init[key] for key in free], 60 * len(free))
        init.update(zip(free, res.x))
        data = data.with_noise(_estimated_noise(first, res.x))
    problem = _Problem(data, model, free, values, tick)
    res = _solve(problem, [init[key] for key in free], 60 * len(free))
    if data.shared is not None and not data.shared_model:   # the rows' shared M00 noise along the model's r
        data = data.with_shared(problem.prediction(problem.unpack(res.x)))
        problem = _Problem(data, model, free, values, tick)
        res = _solve(problem, res.x, 60 * len(free))
    fitted = _uncertainty(problem, res)
    fitted.fixed_by_user = user_fixed
    fitted.notes += notes
    return fitted


def check_enough(data: LabData, free: list):
    """UsageError when there are fewer measured values than parameters to fit (refused, not attempted)."""
    if data.y.size < len(free):
        names = ", ".join(q for q in PARAMETERS if any(k[0] == q for k in free))
        raise UsageError(f"too few data to fit {names}: {data.y.size} measured value(s) for {len(free)} parameters "
                         "-- measure more angles or elements, or fix parameters at known values")


def _estimated_noise(problem: _Problem, x) -> np.ndarray:
    """Noise from the residuals of a first pass: M00 relative (its rms relative misfit), the
    normalized elements absolute (their rms misfit), floored so that weights stay finite."""
    data = problem.data
    f = problem.prediction(problem.unpack(x))
    N = data.geometries
    y00 = np.abs(data.y[:N])
    parts = []
    for c, name in enumerate(data.columns):
        y, m = data.y[c * N:(c + 1) * N], f[c * N:(c + 1) * N]
        if name == M00 or data.absolute:     # relative to M00 (absolute elements' noise scales with it)
            rel = float(np.sqrt(np.mean(((m - y) / np.maximum(y00, 1e-300)) ** 2)))
            parts.append(max(rel, 1e-6) * y00 + 1e-9 * y00.max())
        else:
            parts.append(np.full(N, max(float(np.sqrt(np.mean((m - y) ** 2))), 1e-7)))
    return np.concatenate(parts)


def _uncertainty(problem: _Problem, res) -> ModelFit:
    """Covariance, verdict and notes of a solved problem (module docstring)."""
    data = problem.data
    r = np.asarray(res.fun, float)
    J = np.asarray(res.jac, float)
    chi2 = float(r @ r)
    m, p = r.size, len(problem.free)
    dof = m - p
    names = [param_name(data, key) for key in problem.free]
    cov, corr, diag = _covariance(J, names)
    notes, scale = [], 1.0
    finite = bool(np.all(np.isfinite(cov)))
    if data.sigma_given and dof > 0 and finite:
        scale, cov = birge_scaling(chi2, dof, cov, notes)
    ti, tr, ph = data.angles()
    if data.sigma_given:
        verdict = chi2_verdict(chi2, dof, r.reshape(len(data.columns), -1), ti, tr, ph, data.neighbours(),
                               parameters=len({q for q, _ in problem.free}))
        if not verdict.adequate and "p_value" in verdict.figures:     # (too few geometries: no chi^2 test)
            _name_the_columns(verdict, data, r)
    else:
        verdict = _floor_verdict(problem, res.x, ti, tr, ph)
    if finite and (verdict.errors == "robust" or (data.sigma_given and verdict.errors != "classic")):
        th, td = half_angles(ti, tr, ph)       # where the misfit is systematic: the larger of classic and robust
        cov = larger_errors(cov, cluster_covariance(J, r, np.tile(geometry_clusters(th, td), len(data.columns))))
    values = problem.unpack(res.x)
    stderr = {key: float(math.sqrt(cov[i, i])) if math.isfinite(cov[i, i]) else math.inf
              for i, key in enumerate(problem.free)}
    diag += _parameter_notes(values, stderr, correlation(cov) if finite else corr, problem.free, names, dof)
    if not res.success:
        diag.append(f"the optimizer did not converge: {res.message}")
    return ModelFit(problem.model, data, values, list(problem.free), stderr, cov, chi2, dof, r, bool(res.success),
                    str(res.message), int(res.nfev), verdict, warnings=diag, notes=notes, stderr_scale=scale)


def _covariance(J, names):
    """(J^T J)^-1, its correlation, and a note when J is singular, from the eigen-decomposition of the
    column-scaled J^T J (a p x p problem: no SVD of the tall J).  Singular: a scaled condition number
    of J above 1e7 (its square, J^T J's, near the float64 resolution; a correlation of 1 - 1e-8 is
    still resolved): the data do not separate the parameters, and the errors are infinite."""
    scale = np.sqrt(np.einsum("ij,ij->j", J, J))
    p = len(names)
    usable = np.all(np.isfinite(scale)) and np.all(scale > 0)
    lam, V = np.linalg.eigh((J / scale).T @ (J / scale)) if usable else (np.zeros(p), np.eye(p))
    if not (lam[0] > 1e-14 * lam[-1]):
        corr = np.where(np.eye(p, dtype=bool), 1.0, np.nan)
        cond = math.sqrt(lam[-1] / lam[0]) if lam[0] > 0 else math.inf
        return np.full((p, p), np.inf), corr, [f"the Jacobian is singular (condition number {cond:.3g}): the data "
                                               f"do not constrain {', '.join(names)} separately; standard errors "
                                               "are infinite"]
    cov = ((V / lam) @ V.T) / np.outer(scale, scale)
    return cov, correlation(cov), []


def _name_the_columns(verdict: Verdict, data: LabData, r) -> None:
    """An inadequate chi^2 verdict's cause from where the misfit is: the value column that carries
    the largest share of chi^2 (M00, the lobe; an element, the polarization)."""
    share = (r.reshape(len(data.columns), -1) ** 2).sum(axis=1)
    share = share / max(share.sum(), 1e-300)
    order = np.argsort(-share)
    top = ", ".join(f"{data.columns[i]} {100 * share[i]:.0f} %" for i in order[:3])
    lobe = data.columns[order[0]] == M00
    what = ("the lobe does not fit (its shape: the facet distribution or the shadowing; or the diffuse part)"
            if lobe else "the polarization does not fit (the index, a retardance or polarizing part the model lacks, "
                         "or the diffuse part's depolarization)")
    f = verdict.figures
    verdict.cause = f"{what}; the largest shares of chi^2: {top}"
    verdict.message = (f"reduced chi^2 = {f['reduced_chi2']:.4g} (chi^2 = {f['chi2']:.4g} for {f['dof']} dof, "
                       f"p = {f['p_value']:.3g}): {verdict.cause}")


def _floor_verdict(problem: _Problem, x, ti, tr, ph) -> Verdict:
    """The verdict without sigmas: M00's relative and the elements' absolute misfit against the
    data's own scatter (:func:`hyde_bsdf.fit.adequacy.floor_verdict`)."""
    data = problem.data
    N = data.geometries
    f = problem.prediction(problem.unpack(x))
    resid = (f - data.y).reshape(len(data.columns), N)
    m00 = None
    if data.has_m00:
        m00 = (resid[0] / np.maximum(np.abs(data.y[:N]), 1e-300))[None]
        resid = resid[1:] / np.maximum(f[:N], 1e-300)        # absolute elements: as normalized ones
    elements = resid[None] if resid.shape[0] else np.zeros((1, 1, N))
    return floor_verdict(m00, elements, ti, tr, ph, data.neighbours(), parameters=len({q for q, _ in problem.free}))


def _parameter_notes(values, stderr, corr, free, names, dof) -> list:
    """Ill-posedness notes: no degrees of freedom, strong correlations, large relative errors,
    values on their bounds."""
    notes = []
    if dof == 0:
        notes.append("as many parameters as values: no degrees of freedom, the fit cannot be checked")
    for i in range(len(free)):
        for j in range(i + 1, len(free)):
            c = corr[i, j]
            if math.isfinite(c) and abs(c) > 0.999:
                notes.append(f"{names[i]} and {names[j]} are strongly correlated (rho = {c:+.4f}): the data "
                             "determine a combination of them rather than each one")
    for i, key in enumerate(free):
        v, e = values[key], stderr[key]
        if math.isfinite(e) and v != 0 and e > 0.5 * abs(v):
            notes.append(f"{names[i]} is poorly determined: {v:.4g} +- {e:.3g} ({100 * e / abs(v):.0f} %)")
        lo, hi = BOUNDS[key[0]]
        if key[0] != "diffuse_reflectance" and (v <= lo + 1e-6 * max(1.0, abs(lo)) or v >= hi * (1 - 1e-9)):
            notes.append(f"{names[i]} = {v:.4g} sits on its bound [{lo:g}, {hi:g}]: its standard error does not "
                         "describe the uncertainty")
    return notes


def blame_fixed(data: LabData, fitted: ModelFit, tick=None) -> ModelFit | None:
    """A misfit with parameters held fixed: the same model with every parameter free.  Returns the
    free fit when it describes the data (or fits significantly better), after rewriting ``fitted``'s
    verdict and notes to name the fixed parameters as the cause
    (:func:`hyde_bsdf.fit.adequacy.blame_fixed_parameters`); None when freeing them does not help
    (then the verdict stands)."""
    if fitted.verdict.adequate or not fitted.fixed_by_user:
        return None
    free = fit_model(data, fitted.model, fit=PARAMETERS, values=fitted.values, start=fitted.values, tick=tick)
    held = ", ".join(f"{q} = {fitted.values.get((q, None), fitted.values.get((q, 0))):.4g}"
                     for q in fitted.fixed_by_user if any(k[0] == q for k in fitted.values))
    freed = ", ".join(f"{free.name(k)} = {free.values[k]:.4g}" for k in free.free if k[0] in fitted.fixed_by_user)
    if not blame_fixed_parameters(fitted.verdict, fitted.notes, fitted.chi2, fitted.dof,
                                  (free.chi2, free.dof, free.verdict.adequate), held, freed):
        return None
    return free
