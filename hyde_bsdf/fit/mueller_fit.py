"""Fitting the pBRDF (paper Eq. 17) to normalized Mueller-matrix measurements.

    minimize  chi^2 = sum_e sum_m ((F_e(theta_m; p) / F_00(theta_m; p) - y_em) / sigma_em)^2

over any subset p of (n, k, rms_slope), with ``scipy.optimize.least_squares``
(trust-region reflective, bounds n, k >= 0 and rms_slope > 0), F the Mueller
pBRDF of :func:`hyde_bsdf.pbrdf` and y the measured elements M_jk / M_00 (as
the paper's Figs. 8-9 plot them).

Conventions (this interface)
----------------------------
- Angles in radians (degrees only in CSV files and on the command line):
  theta_i, theta_r polar angles towards source and detector, phi = phi_r - phi_i,
  phi = pi the specular plane (the paper's Figs. 8-9), phi = 0 backscatter.
- Index: the paper's eta = n - jk (e^{+jwt}), ``n``, ``k`` >= 0, as the evaluator.
  The Mitsuba ``hyde`` plugin takes ``eta``, ``k`` meaning n + ik: the **same
  numbers** (eta = n, k = k) describe the same material, the Mueller matrix is
  identical.  :meth:`FitResult.plugin_dict` / :meth:`FitResult.plugin_xml` write them so.
- Roughness ``rms_slope`` = sqrt(2) sigma_h / ell (the paper's and the plugin's name;
  Beckmann alpha = sqrt(2) rms_slope).
- Elements are in the paper's s/p Stokes bases (see :mod:`hyde_bsdf.model.evaluator`).

Uncertainties
-------------
With ``sigma`` the standard errors are sqrt(diag((J^T J)^-1)) of the Jacobian J of
the weighted residuals at the solution (the usual linearized covariance; chi^2
and reduced chi^2 test whether sigma and the model are right).  Without
``sigma`` all values weigh 1 and the covariance is scaled by chi^2 / dof (noise
estimated from the residual scatter).  The correlation matrix is reported with
every fit, and ill-posed fits (too few data, a singular Jacobian, |correlation|
above ``corr_limit``, relative errors above 50 %, a parameter on its bound) warn
with :class:`IllPosedFitWarning` or, with ``strict=True``, raise
:class:`IllPosedFitError`.  Fewer data than fitted parameters always raise.

Every result carries a verdict (``FitResult.verdict``, :mod:`hyde_bsdf.fit.adequacy`): with
sigmas, chi^2 and its p-value (p < 0.001: the model, or the sigmas, do not describe the data --
:class:`InadequateModelWarning`, or :class:`InadequateModelError` with ``strict``, and the errors
are lower bounds); without, the systematic part of the misfit against the data's scatter.  Where
the misfit is systematic each error is the larger of the classic and the cluster-robust one.
:func:`hyde_bsdf.fit.model_selection.select_model` chooses the shadowing and diffuse terms.

What the data can and cannot say (:class:`FitDataWarning`, ``FitResult.data_warnings``):

- *Repeated geometries* (rows with the same theta_i, theta_r, phi) are detected and
  reported, and merged into one value per geometry before the fit: the inverse-variance
  mean, whose sigma is sigma / sqrt(repeats) for genuine repeats (widened by their own
  scatter when it exceeds sigma), and the single-row sigma for identical copies, which
  add no information.  A million copies of one row give the standard errors of one row.
- *Reduced chi^2 far from 1* (p < 0.001 in a tail of the chi^2 distribution): far above,
  the standard errors are multiplied by sqrt(chi^2_red) (the Birge ratio,
  ``FitResult.stderr_scale``) and, above 2, a warning says the sigmas or the model do not
  describe the data; far below (under 0.5) a warning says the sigmas are too large or
  the rows not independent -- the errors are then never scaled down (noiseless data
  would get zero errors).
- *Impossible data*: a normalized element |M_jk / M_00| > 1, or a degree of polarization
  sqrt(M01^2 + M02^2 + M03^2) (or of the first column) > 1, beyond what the noise reaches by
  chance (3 standard deviations, more for many values: ``io.measurements.impossible_limit``)
  (the given sigma, or the fit's residual scatter without sigma): no Mueller matrix has
  them, so the summary never reports a plain "converged".

The command line (``hyde-bsdf fit DATA.csv``, the plot) is :mod:`hyde_bsdf.app.fit`; the CSV
format is :mod:`hyde_bsdf.io.measurements`.  Large data sets report progress through the
``progress`` callback; 10^6 rows read and fit in about 20-30 s on 2 cores
(``hyde_bsdf/validation/fit_synthetic.py``, part 5).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from hyde_bsdf.errors import RejectedResult, UsageError, UsageTypeError, shorten
from hyde_bsdf.model.checks import real_array
from hyde_bsdf.options import Options
from hyde_bsdf.progress import PROGRESS_SECONDS, EvaluationCounter, as_callback, check_progress
from hyde_bsdf.model.evaluator import pbrdf
from hyde_bsdf.model.index import Index
from hyde_bsdf.model.index import admissible
from hyde_bsdf.model.parameters import FIT_PARAMETERS, NATURAL_INDEX, RMS_SLOPE
from hyde_bsdf.model.terms import check_pair
from hyde_bsdf.fit.adequacy import (ERRORS_NOTE, InadequateModelError, InadequateModelWarning, Verdict,
                                    birge_scaling, blame_fixed_parameters, chi2_sf, chi2_verdict, cluster_covariance,
                                    correlation, floor_verdict, geometry_clusters, half_angles, json_number,
                                    larger_errors)
from hyde_bsdf.io.measurements import (ELEMENT_LIMIT, ELEMENT_NAMES, SIGMA_RANGE, Measurements, element_index,
                                       impossible_limit)

__all__ = ["PARAMETERS", "FIT_PARAMETERS", "SEARCH_ROWS", "FitOptions", "FitResult", "check_options", "IllPosedFitWarning",
           "IllPosedFitError", "FitDataWarning", "InadequateModelWarning", "InadequateModelError",
           "merge_repeated_geometries", "impossible_values",
           "mueller_elements", "fit_mueller", "fit_measurements", "synthetic_measurements",
           ]

#: fittable parameters (``parameters.FIT_PARAMETERS``: the evaluator's names, paper index n - jk),
#: in this order everywhere (vectors, covariance, correlation)
PARAMETERS = FIT_PARAMETERS
#: search bounds (``hyde_bsdf.model.parameters``): n, k in NATURAL_INDEX, rms_slope the accepted range
BOUNDS = {"n": NATURAL_INDEX.bounds, "k": NATURAL_INDEX.bounds, "rms_slope": RMS_SLOPE.bounds}
#: start points tried when n0 / k0 are not given (metals and dielectrics alike)
DEFAULT_STARTS = {"n": (0.3, 1.5), "k": (0.5, 3.0, 9.0)}
#: above this many geometries the multi-start search runs on a random subset of this size
#: (fixed seed) and only its best point is refined on all the data (see fit_mueller)
SEARCH_ROWS = 4000


class IllPosedFitWarning(UserWarning):
    """The data do not determine the fitted parameters well (see the message)."""


class IllPosedFitError(RejectedResult):
    """Raised instead of :class:`IllPosedFitWarning` when ``strict=True`` (a ``ValueError``)."""


class FitDataWarning(UserWarning):
    """The data repeat geometries, do not match their sigmas (chi^2_red far from 1), or are impossible."""




def merge_repeated_geometries(theta_i, theta_r, phi, values, sigma=None):
    """Merge rows that repeat a geometry (same theta_i, theta_r and phi modulo 2 pi) into one.

    Parameters: 1-D arrays of one length; ``values`` and ``sigma`` dicts element -> 1-D array
    (``sigma`` None: unit weights).  Returns ``(theta_i, theta_r, phi, values, sigma, info)``
    with one row per distinct geometry (in sorted geometry order when anything was merged,
    else the inputs unchanged) and ``info`` None when no geometry repeats, else a dict
    ``rows``, ``geometries``, ``repeated_rows``, ``copy_geometries`` (geometries whose rows
    are identical copies), ``most`` (the most repeated geometry (theta_i, theta_r, phi) in
    radians) and ``most_count``.

    Merged value: the inverse-variance mean (the plain mean without sigma).  Merged sigma:
    genuine repeats (values differ) give 1 / sqrt(sum 1 / sigma^2), widened by the Birge
    ratio sqrt(chi^2 / (count - 1)) of their own scatter when that exceeds 1; identical
    copies give sqrt(count / sum 1 / sigma^2) -- the single-row sigma: a copied row adds
    no information.  Without sigma every merged value weighs 1.
    """
    ti, tr = np.asarray(theta_i, float), np.asarray(theta_r, float)
    ph = np.mod(np.asarray(phi, float), 2.0 * math.pi)
    rows = ti.size
    order = np.lexsort((ph, tr, ti))
    a, b, c = ti[order], tr[order], ph[order]
    new = np.ones(rows, bool)
    new[1:] = (a[1:] != a[:-1]) | (b[1:] != b[:-1]) | (c[1:] != c[:-1])
    if new.all():
        return theta_i, theta_r, phi, values, sigma, None
    starts = np.flatnonzero(new)
    counts = np.diff(np.append(starts, rows))
    member = np.cumsum(new) - 1
    identical = np.ones(starts.size, bool)
    out_v, out_s = {}, ({} if sigma is not None else None)
    for name, v in values.items():
        v = np.asarray(v, float)[order]
        same = np.maximum.reduceat(v, starts) == np.minimum.reduceat(v, starts)
        identical &= same
        if sigma is None:
            out_v[name] = np.add.reduceat(v, starts) / counts
            continue
        wt = 1.0 / np.asarray(sigma[name], float)[order] ** 2
        W = np.add.reduceat(wt, starts)
        mean = np.add.reduceat(wt * v, starts) / W
        scatter = np.add.reduceat(wt * (v - mean[member]) ** 2, starts)
        with np.errstate(invalid="ignore", divide="ignore"):
            birge = np.where(counts > 1, np.sqrt(scatter / np.maximum(counts - 1, 1)), 1.0)
        out_v[name] = mean
        out_s[name] = np.where(same, np.sqrt(counts / W), np.maximum(birge, 1.0) / np.sqrt(W))
    most = int(np.argmax(counts))
    info = {"rows": rows, "geometries": int(starts.size), "repeated_rows": int(rows - starts.size),
            "copy_geometries": int(np.count_nonzero(identical & (counts > 1))),
            "most": (float(a[starts[most]]), float(b[starts[most]]), float(c[starts[most]])),
            "most_count": int(counts[most])}
    return a[starts], b[starts], c[starts], out_v, out_s, info


def impossible_values(values, noise, limit: float | None = None) -> list:
    """Values no Mueller matrix can have, beyond ``limit`` x ``noise`` (None: what the noise of that
    many values reaches with probability 0.001, at least 3:
    :func:`hyde_bsdf.io.measurements.impossible_limit`, as the CSV reader judges -- honest data at
    the edge of the range pass, whatever their number).

    ``values``: element -> normalized values M_jk / M00 (1-D arrays of one length);
    ``noise``: element -> their standard deviations (arrays or scalars).  Checks |M_jk/M00| <= 1
    and the degrees of polarization sqrt(M01^2 + M02^2 + M03^2) <= 1 (output of unpolarized
    light) and sqrt(M10^2 + M20^2 + M30^2) <= 1 (diattenuation), over the elements present.
    Returns a list of (what, row index, value, its sigma, limit) for each failing check's worst row.
    """
    found = []
    if limit is None:
        limit = impossible_limit(sum(np.size(v) for v in values.values()))
    for name, v in values.items():
        v = np.asarray(v, float)
        s = np.broadcast_to(np.asarray(noise[name], float), v.shape)
        excess = (np.abs(v) - 1.0) / s
        bad = excess > limit
        if bad.any():
            i = int(np.argmax(np.where(bad, excess, -np.inf)))
            found.append((f"|{name}/M00| > 1 in {int(bad.sum())} row(s)", i, float(v[i]), float(s[i]), limit))
    for label, group in (("degree of polarization sqrt(M01^2+M02^2+M03^2)", ("M01", "M02", "M03")),
                         ("diattenuation sqrt(M10^2+M20^2+M30^2)", ("M10", "M20", "M30"))):
        present = [g for g in group if g in values]
        if len(present) < 2:
            continue
        vs = [np.asarray(values[g], float) for g in present]
        ss = [np.broadcast_to(np.asarray(noise[g], float), vs[0].shape) for g in present]
        dop = np.sqrt(sum(x * x for x in vs))
        with np.errstate(invalid="ignore", divide="ignore"):
            sd = np.sqrt(sum((x * e) ** 2 for x, e in zip(vs, ss))) / np.where(dop > 0, dop, 1.0)
            excess = (dop - 1.0) / np.maximum(sd, 1e-300)
        bad = excess > limit
        if bad.any():
            i = int(np.argmax(np.where(bad, excess, -np.inf)))
            found.append((f"{label} > 1 in {int(bad.sum())} row(s)", i, float(dop[i]), float(sd[i]), limit))
    return found


def mueller_elements(theta_i, theta_r, phi, names, *, rms_slope, n, k,
                     shadowing="vgroove", diffuse=True) -> dict:
    """Normalized pBRDF elements F_jk / F_00 (paper Eq. 17) for element names like ``"M23"``.

    Angles in radians (broadcast together), eta = n - jk.  Returns a dict name ->
    ndarray of the broadcast shape.  Geometries with F_00 = 0 (at or below the
    horizon) raise UsageError (a ValueError): a normalized element is undefined there.
    """
    return _elements(theta_i, theta_r, phi, names, rms_slope=rms_slope, n=n, k=k, shadowing=shadowing,
                     diffuse=diffuse, strict=True)


def _elements(theta_i, theta_r, phi, names, *, rms_slope, n, k, shadowing, diffuse, strict):
    """F_jk / F_00; where F_00 = 0 above the horizon (the lobe underflows far from the specular
    direction without a diffuse term, as the fit may try) 0 unless ``strict``."""
    F = pbrdf(theta_i, theta_r, phi, rms_slope=rms_slope, n=n, k=k, shadowing=shadowing,
              diffuse=diffuse)
    F00 = F[..., 0, 0]
    if np.any(F00 <= 0.0):
        if strict:
            raise UsageError("theta_i and theta_r must be below 90 deg (pi/2): F_00 = 0 there and "
                             "normalized Mueller elements are undefined")
        F00 = np.where(F00 > 0.0, F00, np.inf)
    return {name: F[(...,) + element_index(name)] / F00 for name in names}


@dataclass
class FitResult:
    """Result of :func:`fit_mueller`.

    Attributes
    ----------
    params : dict n, k, rms_slope -> value (fitted or held fixed); eta = n - jk
    fitted : names of the fitted parameters, the order of ``covariance``/``correlation``
    stderr : dict fitted name -> standard error (inf when the data do not constrain it)
    covariance, correlation : ndarray (p, p)
    chi2, dof, reduced_chi2, p_value : goodness of fit (p_value = P(chi^2_dof >= chi2))
    residuals : dict element -> normalized residuals (model - data) / sigma
    success : the optimizer converged (``message`` says how)
    sigma_given : whether chi^2 uses the given sigma (else unit weights)
    warnings : the ill-posedness diagnostics (also issued as IllPosedFitWarning)
    verdict : :class:`~hyde_bsdf.fit.adequacy.Verdict`, whether the model describes the data
        (chi^2 p-value with sigmas, the misfit against the data's floor without) and what the
        standard errors mean (classic, robust, or lower bounds)
    """

    params: dict
    fitted: tuple
    stderr: dict
    covariance: np.ndarray
    correlation: np.ndarray
    chi2: float
    dof: int
    reduced_chi2: float
    p_value: float
    residuals: dict
    success: bool
    message: str
    nfev: int
    n_data: int
    sigma_given: bool
    shadowing: str = "vgroove"
    diffuse: str = "paper"
    warnings: list = field(default_factory=list)
    condition_number: float = float("nan")
    rows: int = 0
    repeats: dict | None = None
    stderr_scale: float = 1.0
    data_warnings: list = field(default_factory=list)
    verdict: Verdict | None = None

    @property
    def ill_posed(self) -> bool:
        return bool(self.warnings)

    @property
    def index(self) -> Index:
        """The fitted (or fixed) index n + ik."""
        return Index(self.params["n"], self.params["k"])

    def model(self, theta_i, theta_r, phi, names=("M01", "M11", "M22", "M23")) -> dict:
        """The fitted model's normalized elements at other geometries (radians)."""
        return mueller_elements(theta_i, theta_r, phi, names, **self.params,
                                shadowing=self.shadowing, diffuse=self.diffuse)

    def correlation_of(self, a: str, b: str) -> float:
        """Correlation coefficient between two fitted parameters (nan if either is fixed)."""
        if a not in self.fitted or b not in self.fitted:
            return float("nan")
        return float(self.correlation[self.fitted.index(a), self.fitted.index(b)])

    # ---- loading the fitted material into a scene
    def to_dict(self, models: list | None = None) -> dict:
        """The machine-readable result in a lab fit's schema (:meth:`hyde_bsdf.fit.lab.LabFitResult.to_dict`):
        n, k, rms_slope (no wavelength; stderr None where held fixed), the covariance of the fitted
        ones, the verdict (p_value None without sigmas), the warnings.  ``models``: a model
        selection's table (:meth:`~hyde_bsdf.fit.model_selection.ModelSelection.to_dict`), else this
        fit alone."""
        params = [{"name": q, "wavelength_nm": None, "value": json_number(self.params[q]),
                   "stderr": json_number(self.stderr[q]) if q in self.fitted else None} for q in PARAMETERS]
        row = {"shadowing": self.shadowing, "diffuse": self.diffuse, "dielectric": "k" not in self.fitted and
               self.params["k"] == 0, "free_parameters": len(self.fitted), "adequate": bool(self.verdict.adequate),
               "chosen": True, "values": {q: float(self.params[q]) for q in PARAMETERS}}
        return {"model": {"shadowing": self.shadowing, "diffuse": self.diffuse},
                "parameters": params,
                "covariance": {"names": list(self.fitted),
                               "matrix": [[json_number(x) for x in r] for r in np.asarray(self.covariance, float)]},
                "verdict": {"adequate": bool(self.verdict.adequate), "chi2_reduced": json_number(self.reduced_chi2),
                            "p_value": json_number(self.p_value) if self.sigma_given else None,
                            "warnings": list(self.data_warnings) + list(self.warnings)
                            + ([] if self.verdict.adequate else [self.verdict.message])},
                "models": [row] if models is None else models}

    def plugin_dict(self) -> dict:
        """The ``hyde`` plugin's dict for ``mi.load_dict``.

        The plugin's ``eta``, ``k`` are Mitsuba's n + ik (:meth:`Index.mitsuba`); the paper's
        eta = n - jk is the same material with the same numbers: eta = n, k = k.
        """
        s = self.params["rms_slope"]    # inside parameters.RMS_SLOPE (BOUNDS), which the plugin accepts
        return {"type": "hyde", "rms_slope": float(s), **self.index.mitsuba(),
                "shadowing": self.shadowing, "diffuse": self.diffuse}

    def plugin_xml(self, indent: str = "") -> str:
        """The same as :meth:`plugin_dict`, as a Mitsuba XML ``<bsdf>`` element."""
        d = self.plugin_dict()
        lines = [f'{indent}<bsdf type="hyde">',
                 f'{indent}    <float name="rms_slope" value="{d["rms_slope"]:.6g}"/>',
                 f'{indent}    <!-- Mitsuba n + ik; the paper writes eta = {d["eta"]:.6g} - j{d["k"]:.6g} -->',
                 f'{indent}    <float name="eta" value="{d["eta"]:.6g}"/>',
                 f'{indent}    <float name="k" value="{d["k"]:.6g}"/>',
                 f'{indent}    <string name="shadowing" value="{d["shadowing"]}"/>',
                 f'{indent}    <string name="diffuse" value="{d["diffuse"]}"/>',
                 f'{indent}</bsdf>']
        return "\n".join(lines)

    def summary(self) -> str:
        """A human-readable report of the fit."""
        out = [f"pBRDF fit (paper Eq. 17; shadowing={self.shadowing!r}, diffuse={self.diffuse!r}): "
               f"{self.n_data} values, {len(self.fitted)} fitted parameters"]
        vd = self.verdict
        caveat = (" -- but the model does NOT describe the data (WARNING below)" if vd is not None and not vd.adequate
                  else " -- but the data warnings below limit what it means" if self.data_warnings else "")
        out.append(f"  optimizer converged: {self.success} ({self.message}; {self.nfev} model evaluations){caveat}")
        if self.repeats:
            rp = self.repeats
            out.append(f"  repeated geometries: {rp['repeated_rows']} of {rp['rows']} rows repeat another row's "
                       f"geometry; fitted {rp['geometries']} distinct geometries")
        if self.stderr_scale != 1.0:
            out.append(f"  standard errors scaled by sqrt(reduced chi^2) = {self.stderr_scale:.4g}")
        for name in PARAMETERS:
            v = self.params[name]
            if name in self.fitted:
                e = self.stderr[name]
                rel = f" ({100 * e / abs(v):.2g} %)" if v != 0 and math.isfinite(e) else ""
                out.append(f"  {name:9s} = {v:.6g} +- {e:.3g}{rel}")
            else:
                out.append(f"  {name:9s} = {v:.6g} (fixed)")
        n, k = self.index.n, self.index.k
        out.append(f"  index: paper eta = {n:.6g} - j{k:.6g};  Mitsuba/plugin eta = {n:.6g}, k = {k:.6g} (n + ik)")
        tag = "" if self.sigma_given else "  [no sigma given: unit weights, errors scaled by the residual scatter]"
        out.append(f"  chi^2 = {self.chi2:.4g}, dof = {self.dof}, reduced chi^2 = {self.reduced_chi2:.4g}, "
                   f"p = {self.p_value:.3g}{tag}")
        if len(self.fitted) > 1:
            out.append("  correlation matrix:")
            out.append("    " + " " * 10 + "".join(f"{n:>10s}" for n in self.fitted))
            for i, a in enumerate(self.fitted):
                out.append(f"    {a:10s}" + "".join(f"{self.correlation[i, j]:10.4f}"
                                                    for j in range(len(self.fitted))))
        if vd is not None:
            out.append(f"  model {vd.line()}")
            out.append("  standard errors: " + ERRORS_NOTE[vd.errors])
        for w in self.warnings + self.data_warnings + ([vd.message] if vd is not None and not vd.adequate else []):
            out.append(f"  WARNING: {w}")
        return "\n".join(out)


def _as_arrays(theta_i, theta_r, phi, measured, sigma):
    if not isinstance(measured, dict) or not measured:
        raise UsageError(f"measured must be a non-empty dict of element name -> array "
                         f"(names {', '.join(ELEMENT_NAMES)}), got {shorten(measured)}")
    if sigma is not None and not isinstance(sigma, dict):
        raise UsageTypeError(f"sigma must be None or a dict of element name -> standard deviations, "
                             f"got {type(sigma).__name__}")
    angles = []
    for name, a, hi in (("theta_i", theta_i, math.pi / 2), ("theta_r", theta_r, math.pi / 2),
                        ("phi", phi, None)):
        a = real_array(name, a, "radians")
        if hi is not None and np.any((a < 0) | (a >= hi)):
            raise UsageError(f"{name} must be in [0, pi/2) radians (the detector and source above the surface)")
        angles.append(a)
    try:
        shape = np.broadcast_shapes(*(a.shape for a in angles))
    except ValueError:
        raise UsageError(f"theta_i, theta_r, phi must broadcast to one shape, got "
                         f"{', '.join(str(a.shape) for a in angles)}") from None
    values, sig = {}, {}
    for name, v in measured.items():
        element_index(name)
        v = real_array(f"measured[{name!r}]", v, "M_jk / M_00")
        try:
            shape = np.broadcast_shapes(shape, v.shape)
        except ValueError:
            raise UsageError(f"measured[{name!r}] has shape {v.shape}, which does not broadcast with "
                             f"the angles' shape {shape}") from None
        if sigma is None and np.any(np.abs(v) > ELEMENT_LIMIT):
            worst = float(v.flat[np.argmax(np.abs(v))])
            raise UsageError(f"measured[{name!r}] must be normalized by M00 (|M_jk/M_00| <= {ELEMENT_LIMIT:g}; "
                             f"<= 1 for a physical Mueller matrix), got {worst:g}: divide the elements by M00")
        values[name] = v
        if sigma is not None:
            if name not in sigma:
                raise UsageError(f"sigma has no entry for measured element {name!r}")
            s = real_array(f"sigma[{name!r}]", sigma[name], "standard deviations")
            if np.any(s <= 0):
                raise UsageError(f"sigma[{name!r}] must be finite and > 0")
            if np.any((s < SIGMA_RANGE[0]) | (s > SIGMA_RANGE[1])):
                raise UsageError(f"sigma[{name!r}] must be in [{SIGMA_RANGE[0]:g}, {SIGMA_RANGE[1]:g}] "
                                 f"(standard deviations of normalized elements), got values from "
                                 f"{s.min():g} to {s.max():g}")
            try:
                np.broadcast_shapes(shape, s.shape)
            except ValueError:
                raise UsageError(f"sigma[{name!r}] has shape {s.shape}, which does not broadcast with "
                                 f"the data's shape {shape}") from None
            sig[name] = s
            _judge_by_sigma(name, v, s)
    if sigma is not None:
        extra = set(sigma) - set(measured)
        if extra:
            raise UsageError(f"sigma has entries {sorted(extra)} with no measured values")
    ti, tr, ph = (np.broadcast_to(a, shape).ravel() for a in angles)
    y = {n: np.broadcast_to(v, shape).ravel() for n, v in values.items()}
    w = {n: np.broadcast_to(sig[n], shape).ravel() if sigma is not None else np.ones(ti.size)
         for n in values}
    return ti, tr, ph, y, w, shape


def _judge_by_sigma(name, v, s):
    """A normalized value with a sigma is judged against it, as the CSV reader does
    (:func:`hyde_bsdf.io.measurements.impossible_limit`): within the limit of the range |M_jk/M00| <= 1
    it is data; beyond, impossible at its stated error: refused, naming the worst."""
    v, s = np.broadcast_arrays(v, s)
    excess = (np.abs(v) - 1.0) / s
    limit = impossible_limit(v.size)
    if np.any(excess > limit):
        i = int(np.argmax(excess))
        raise UsageError(f"measured[{name!r}] = {float(v.flat[i]):g} +- {float(s.flat[i]):.3g} is not a normalized "
                         f"element: |M_jk/M_00| <= 1 for a physical Mueller matrix, and it lies {float(excess.flat[i]):.3g} "
                         f"standard deviations beyond (values within {limit:.3g} are kept as data): divide the elements "
                         "by M00, or check the sigma")


def _check_fit_names(fit, diffuse_mode="paper"):
    """The fitted names in canonical order; None: every parameter the data determine -- n, k and
    rms_slope, which without a diffuse term the normalized elements do not depend on (then held)."""
    if fit is None:
        return tuple(q for q in PARAMETERS if q != "rms_slope" or diffuse_mode != "none")
    if isinstance(fit, str):
        fit = tuple(p.strip() for p in fit.split(",") if p.strip())
    fit = tuple(fit)
    bad = [p for p in fit if p not in PARAMETERS]
    if bad or not fit or len(set(fit)) != len(fit):
        raise UsageError(f"fit must be a non-empty subset of {PARAMETERS} without repeats, got {fit!r}")
    return tuple(p for p in PARAMETERS if p in fit)   # canonical order


def _start_value(name, value, fitted):
    label = "rms_slope" if name == "rms_slope" else f"{name}0"
    if value is None:
        if name in fitted:
            return None
        raise UsageError(f"{label} must be given when {name} is not fitted (it is then held at that value)")
    if isinstance(value, (bool, np.bool_, str, bytes, complex, np.complexfloating)):
        raise UsageTypeError(f"{label} must be a real number, got {shorten(value)}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise UsageTypeError(f"{label} must be a real number, got {shorten(value)}") from None
    lo, hi = BOUNDS[name]
    if not math.isfinite(v) or not lo <= v <= hi:
        raise UsageError(f"{label} must be in [{lo:g}, {hi:g}], got {shorten(value)}")
    return v


def check_options(fit=None, rms_slope=0.3, n0=None, k0=None, shadowing="vgroove", diffuse=True,
                  corr_limit=0.95):
    """Check :func:`fit_mueller`'s options without data (the command line does so before it
    reads a large file); returns (fitted names, diffuse mode, start/fixed values)."""
    term = check_pair(shadowing, diffuse)[1]       # the rules of model/terms.py
    fitted = _check_fit_names(fit, term.name)
    if term.parameters:
        raise UsageError(f"diffuse={term.name!r} has a free {', '.join(term.parameters)}: fit it with "
                         "hyde_bsdf.fit.lab.fit_lab (fit_mueller fits n, k, rms_slope)")
    mode = term.name
    if isinstance(corr_limit, bool) or not (isinstance(corr_limit, (int, float)) and 0 < corr_limit <= 1):
        raise UsageError(f"corr_limit must be in (0, 1], got {corr_limit!r}")
    given = {"n": _start_value("n", n0, fitted), "k": _start_value("k", k0, fitted),
             "rms_slope": _start_value("rms_slope", rms_slope, fitted)}
    if given["rms_slope"] is None:
        raise UsageError("rms_slope must be given (start value when fitted)")
    return fitted, mode, given


@dataclass(frozen=True)
class FitOptions(Options):
    """The model terms and the reporting of :func:`fit_mueller` (each field is also a keyword of
    :func:`fit_mueller`; its docstring describes them)."""

    shadowing: str = "vgroove"
    diffuse: object = True
    corr_limit: float = 0.95
    strict: bool = False
    progress: object = None


def fit_mueller(theta_i, theta_r, phi, measured, *, sigma=None, fit=None, rms_slope=0.3, n0=None, k0=None,
                options: FitOptions | None = None, **settings) -> FitResult:
    """Least-squares fit of the pBRDF (Eq. 17) to normalized Mueller elements.

    The model terms and the reporting are a :class:`FitOptions` (``options``), or its fields given as
    keywords: ``shadowing``, ``diffuse``, ``corr_limit``, ``strict``, ``progress`` below.

    Parameters
    ----------
    theta_i, theta_r, phi : array_like, radians, broadcast together (shape S)
        measurement geometries (theta in [0, pi/2); phi = pi the specular plane).
    measured : dict element name ("M01", "M11", "M22", "M23", ... any of M01..M33)
        -> array broadcastable to S of M_jk / M_00 (|value| <= 1.5, as the CSV reader).
    sigma : dict of the same names -> standard deviations of those values, in
        [1e-12, 1e3], or None (unit weights; the covariance is then scaled by chi^2 / dof).
    fit : subset of ("n", "k", "rms_slope") (or "n,k,rms_slope") to fit; the others
        are held at their given values.  None (the default): every parameter the data
        determine -- all three, but rms_slope not without a diffuse term (the normalized
        elements do not depend on it then: it is held, and a FitDataWarning says so).  A
        misfit that a parameter held fixed causes is blamed on it, never on the sigmas: the
        fit is repeated with all three free, and when that removes the misfit the verdict
        names the fixed parameter.
    rms_slope : start (if fitted) or fixed value of the paper's sqrt(2) sigma_h / ell.
    n0, k0 : start (if fitted) or fixed value of eta = n - jk (n, k >= 0).  A fitted
        parameter without a start value is started from several points
        (:data:`DEFAULT_STARTS`) and the best fit is kept.
    shadowing, diffuse : passed to :func:`hyde_bsdf.pbrdf` (default: the paper's model).
    corr_limit : |correlation| above which the fit is reported as ill-posed.
    strict : raise :class:`IllPosedFitError` instead of warning.
    progress : a callback ``progress(message)`` told every few seconds, True (lines on stderr),
        False, or None (the default: stderr lines only for more than :data:`SEARCH_ROWS`
        geometries); see :mod:`hyde_bsdf.progress`.

    Large data sets: with more than :data:`SEARCH_ROWS` geometries the multi-start search
    runs on a random subset of that size and only its best point is refined on all the
    data, with a forward-difference Jacobian (4 model evaluations per step instead of 7);
    10^6 geometries fit in about 20 s (``hyde_bsdf/validation/fit_synthetic.py`` measures it).

    Returns
    -------
    FitResult (values, standard errors, covariance, correlation, chi^2, residuals,
    convergence flag, diagnostics; ``plugin_dict()`` / ``plugin_xml()`` for Mitsuba).

    Raises
    ------
    UsageError (a ValueError; TypeError for a value of the wrong kind) for bad input, naming the
    parameter, and when there are fewer measured values than fitted parameters (the fit is
    then undetermined: refused, not attempted).
    """
    o = FitOptions.of(options, settings, "fit_mueller")
    shadowing, diffuse, corr_limit, strict, progress = o.shadowing, o.diffuse, o.corr_limit, o.strict, o.progress
    fitted, mode, given = check_options(fit, rms_slope, n0, k0, shadowing, diffuse, corr_limit)
    check_progress(progress)
    data = _FitData.build(theta_i, theta_r, phi, measured, sigma, fitted)
    report = EvaluationCounter(as_callback(data.large if progress is None else progress),
                               PROGRESS_SECONDS, unit="model evaluations")
    problem = _Objective(data, fitted, given, shadowing, mode, report)
    res, nfev = problem.minimize()
    report.done()
    r = res.fun
    chi2 = float(r @ r)
    m, p = data.ydat.size, len(fitted)
    dof = m - p
    J = np.asarray(res.jac, dtype=float)
    cov, corr, cond, diag = _linear_covariance(J, fitted, data.sigma_given, chi2, dof)
    data_diag = [] if data.repeats is None else [_repeats_note(data.repeats)]
    scale = 1.0
    if data.sigma_given and dof > 0 and math.isfinite(cond) and cond <= 1e10:
        scale, cov = birge_scaling(chi2, dof, cov, data_diag)
    data_diag += _impossible_notes(data, chi2, dof)
    classic = np.sqrt(np.diag(cov))
    verdict, cov = _adequacy(r, J, cov, data.ti, data.tr, data.ph, len(data.names), chi2, dof,
                             data.sigma_given)
    verdict.figures["stderr_classic"] = dict(zip(fitted, classic.tolist()))
    if verdict.errors == "robust" or (not verdict.adequate and np.all(np.isfinite(cov))):
        corr = correlation(cov)
    stderr = {q: float(math.sqrt(cov[i, i])) if math.isfinite(cov[i, i]) else float("inf")
              for i, q in enumerate(fitted)}
    vals = problem.unpack(res.x)
    diag += _parameter_notes(vals, stderr, corr, fitted, corr_limit, m, dof)
    if not res.success:
        diag.append(f"the optimizer did not converge: {res.message}")
    if fit is None and "rms_slope" not in fitted:
        data_diag.append(f"rms_slope is not identified: without a diffuse term the normalized elements do not depend "
                         f"on it; it is held at rms_slope = {vals['rms_slope']:.4g} (give the value you know: a "
                         "material needs it) -- M00 in 1/sr determines it (hyde_bsdf.fit.lab.fit_lab)")
    determined = _check_fit_names(None, mode)      # what the elements depend on: freeing the rest cannot help
    if not verdict.adequate and set(determined) - set(fitted):
        _blame_fixed(verdict, data_diag, vals, fitted, chi2, dof, lambda v: fit_mueller(
            theta_i, theta_r, phi, measured, sigma=sigma, fit=determined, rms_slope=v["rms_slope"], n0=v["n"],
            k0=v["k"], shadowing=shadowing, diffuse=diffuse, corr_limit=corr_limit, progress=False))
    result = FitResult(
        params=vals, fitted=fitted, stderr=stderr, covariance=cov, correlation=corr,
        chi2=chi2, dof=dof, reduced_chi2=chi2 / dof if dof > 0 else float("nan"),
        p_value=float(chi2_sf(chi2, dof)) if dof > 0 else float("nan"),
        residuals=data.split(r), success=bool(res.success), message=str(res.message), nfev=int(nfev),
        n_data=m, sigma_given=data.sigma_given, shadowing=shadowing, diffuse=mode,
        warnings=diag, condition_number=cond, rows=data.rows_in, repeats=data.repeats, stderr_scale=scale,
        data_warnings=data_diag, verdict=verdict)
    for text in data_diag:
        warnings.warn(text, FitDataWarning, stacklevel=2)
    raise_or_warn(verdict, diag, strict, stacklevel=3)
    return result


def _blame_fixed(verdict, notes, vals, fitted, chi2, dof, refit):
    """A misfit with parameters held fixed: ``refit(vals)`` fits every parameter the elements depend
    on, from these values; when that removes the misfit the verdict and the notes name the held
    parameters it freed as its cause (:func:`hyde_bsdf.fit.adequacy.blame_fixed_parameters`)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            free = refit(vals)
        except UsageError:          # fewer values than parameters: nothing to compare
            return
    freed = [q for q in free.fitted if q not in fitted]
    blame_fixed_parameters(verdict, notes, chi2, dof, (free.chi2, free.dof, free.verdict.adequate),
                           ", ".join(f"{q} = {vals[q]:.4g}" for q in freed),
                           ", ".join(f"{q} = {free.params[q]:.4g}" for q in freed))


@dataclass
class _FitData:
    """The measured values as fitted: one row per distinct geometry (repeats merged), the
    elements stacked in ``names`` order into ``ydat`` with weights ``wdat``."""

    ti: np.ndarray
    tr: np.ndarray
    ph: np.ndarray
    y: dict
    w: dict
    names: tuple
    ydat: np.ndarray
    wdat: np.ndarray
    rows_in: int
    repeats: dict | None
    sigma_given: bool

    @classmethod
    def build(cls, theta_i, theta_r, phi, measured, sigma, fitted):
        """Checked, flattened, merged data; refuses fewer values than fitted parameters."""
        ti, tr, ph, y, w, _ = _as_arrays(theta_i, theta_r, phi, measured, sigma)
        rows_in = ti.size
        ti, tr, ph, y, w_merged, repeats = merge_repeated_geometries(ti, tr, ph, y,
                                                                     w if sigma is not None else None)
        if repeats is not None:
            w = w_merged if sigma is not None else {n_: np.ones(ti.size) for n_ in y}
        names = tuple(y)
        ydat = np.concatenate([y[n] for n in names])
        wdat = np.concatenate([w[n] for n in names])
        m, p = ydat.size, len(fitted)
        if m < p:
            merged = (f" ({rows_in} rows, but only {ti.size} distinct geometries: rows that repeat a geometry "
                      "count once)") if repeats is not None else ""
            raise UsageError(f"too few data to fit {', '.join(fitted)}: {m} measured value(s){merged} for {p} "
                             f"parameters -- measure more angles or elements, or fix parameters "
                             f"(fit=...) at known values")
        return cls(ti, tr, ph, y, w, names, ydat, wdat, rows_in, repeats, sigma is not None)

    @property
    def rows(self) -> int:
        return self.ti.size

    @property
    def large(self) -> bool:
        return self.rows > SEARCH_ROWS

    def split(self, r) -> dict:
        """The stacked residual vector back into one array per element."""
        residuals, off = {}, 0
        for n_ in self.names:
            size = self.y[n_].size
            residuals[n_] = r[off:off + size].copy()
            off += size
        return residuals


def recent_points(fn, size: int = 8):
    """``fn(x)`` (arrays, or a tuple of arrays) remembering its last ``size`` points: an optimiser that asks for a
    point again (the base of a Jacobian after a rejected step, the start of a refit) gets copies of the same
    arrays, not a new evaluation of the model (a deterministic ``fn``: the same x, the same bits)."""
    recent = {}

    def call(x):
        key = np.asarray(x, float).tobytes()
        got = recent.get(key)
        if got is None:
            got = fn(x)
            if len(recent) >= size:
                del recent[next(iter(recent))]
            recent[key] = got
        return tuple(a.copy() for a in got) if isinstance(got, tuple) else got.copy()

    return call


class _Objective:
    """The weighted residuals of the fitted parameters and their bounded minimization."""

    def __init__(self, data, fitted, given, shadowing, mode, report):
        self.data, self.fitted, self.given = data, fitted, given
        self.shadowing, self.mode, self.report = shadowing, mode, report
        self.lo = np.array([BOUNDS[q][0] for q in fitted])
        self.hi = np.array([BOUNDS[q][1] for q in fitted])

    def unpack(self, x) -> dict:
        vals = dict(self.given)
        vals.update(zip(self.fitted, (float(v) for v in x)))
        vals["n"], vals["k"] = admissible(vals["n"], vals["k"])      # eta = 0 is not a material
        return vals

    def residual(self, sel):
        """Weighted residuals on the geometries ``sel`` (None: all)."""
        d = self.data
        a, b, c = (d.ti, d.tr, d.ph) if sel is None else (d.ti[sel], d.tr[sel], d.ph[sel])
        if sel is None:
            yd, wd = d.ydat, d.wdat
        else:
            yd = np.concatenate([d.y[n][sel] for n in d.names])
            wd = np.concatenate([d.w[n][sel] for n in d.names])

        @recent_points
        def weighted(x):
            model = _elements(a, b, c, d.names, **self.unpack(x), shadowing=self.shadowing,
                              diffuse=self.mode, strict=False)
            r = (np.concatenate([model[n] for n in d.names]) - yd) / wd
            self.report.tick(r)
            return r
        return weighted

    def starts(self) -> np.ndarray:
        """Every combination of start values (several only for fitted n/k given no start)."""
        grids = [DEFAULT_STARTS[q] if self.given[q] is None else (self.given[q],) for q in self.fitted]
        return np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(self.fitted), -1).T

    def solve(self, fun, x0, jac, max_nfev, tol=1e-12):
        from scipy.optimize import least_squares
        lo, hi = self.lo, self.hi
        x0 = np.clip(x0, lo + 1e-9 * np.maximum(1, np.abs(lo)), hi)   # strictly inside for TRF
        return least_squares(fun, x0, jac=jac, bounds=(lo, hi), x_scale="jac",
                             xtol=tol, ftol=tol, gtol=tol, max_nfev=max_nfev)

    def best_start(self, fun, starts):
        """The lowest-cost solution from every start point, and the evaluations spent."""
        best, nfev = None, 0
        for x0 in starts:
            res = self.solve(fun, x0, "3-point", 100 * len(self.fitted))
            nfev += res.nfev
            if best is None or res.cost < best.cost:
                best = res
        return best, nfev

    def minimize(self):
        """The multi-start fit; with many geometries the search runs on a fixed random subset
        and its best point is refined on everything.  Returns (result, evaluations)."""
        rows, starts = self.data.rows, self.starts()
        if not self.data.large:
            self.report.stage = f"fitting {rows} geometries"
            return self.best_start(self.residual(None), starts)
        sel = np.sort(np.random.default_rng(0).choice(rows, SEARCH_ROWS, replace=False))
        self.report.stage = f"searching {len(starts)} start point(s) on {SEARCH_ROWS} of {rows} geometries"
        best, nfev = self.best_start(self.residual(sel), starts)
        self.report.stage = f"refining on all {rows} geometries"
        # tolerance 1e-9: steps far below the standard errors of 10^4+ geometries (each
        # full-data step costs 4 evaluations of the whole set; 1e-12 only adds steps of ~0)
        res = self.solve(self.residual(None), best.x, "2-point", 30 * len(self.fitted), tol=1e-9)
        return res, nfev + res.nfev


def _linear_covariance(J, fitted, sigma_given, chi2, dof):
    """The linearized covariance (J^T J)^-1 of the weighted residuals (scaled by chi^2 / dof
    without sigmas), its correlation, the condition number, and a note when J is singular."""
    p = len(fitted)
    diag = []
    _, sv, Vt = np.linalg.svd(J, full_matrices=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    if not math.isfinite(cond) or cond > 1e10:
        cov = np.full((p, p), np.inf)
        corr = np.full((p, p), np.nan)
        np.fill_diagonal(corr, 1.0)
        diag.append(f"the Jacobian is singular (condition number {cond:.3g}): the data do not "
                    f"constrain {', '.join(fitted)} separately; standard errors are infinite")
        return cov, corr, cond, diag
    cov = (Vt.T / sv ** 2) @ Vt      # (J^T J)^-1 from the SVD: J^T J squares the condition number
    if not sigma_given and dof > 0:
        cov *= chi2 / dof      # noise level estimated from the residual scatter
    se = np.sqrt(np.diag(cov))
    return cov, cov / np.outer(se, se), cond, diag


def _repeats_note(repeats) -> str:
    """What the merge of repeated geometries did, in one line."""
    t_i, t_r, f_ = (math.degrees(x) for x in repeats["most"])
    return (f"{repeats['repeated_rows']} of {repeats['rows']} rows repeat another row's geometry "
            f"({repeats['geometries']} distinct; the most repeated, theta_i={t_i:.6g}, theta_r={t_r:.6g}, "
            f"phi={f_:.6g} deg, {repeats['most_count']} times); they were merged into one value per "
            "geometry (inverse-variance mean)" +
            (f", and {repeats['copy_geometries']} of the geometries hold only identical copies, which count "
             "once: the standard errors do not shrink with copied rows" if repeats['copy_geometries'] else
             ", its sigma that of the mean of the repeats"))


def _impossible_notes(data, chi2, dof) -> list:
    """Notes on values no Mueller matrix has, beyond :func:`impossible_values`' limit of the noise (the
    given sigmas, or the fit's residual scatter without)."""
    if not data.sigma_given and dof <= 0:
        return []
    noise = data.w if data.sigma_given else {
        n_: np.full(data.rows, math.sqrt(chi2 / dof)) for n_ in data.names}
    bad = impossible_values(data.y, {n_: np.maximum(noise[n_], 1e-12) for n_ in data.names})
    return [f"impossible data: {what} beyond {limit:.2g} sigma (worst {v:.4g} +- {e:.2g} at "
            f"theta_i={math.degrees(data.ti[i]):.4g}, theta_r={math.degrees(data.tr[i]):.4g}, "
            f"phi={math.degrees(data.ph[i]):.4g} deg): no Mueller matrix has it -- unnormalized data or a "
            "calibration error; the fit cannot describe these values"
            for what, i, v, e, limit in bad]


def _parameter_notes(vals, stderr, corr, fitted, corr_limit, m, dof) -> list:
    """Ill-posedness notes: no degrees of freedom, strong correlations, large relative errors,
    values on their bounds."""
    p = len(fitted)
    diag = []
    if dof == 0:
        diag.append(f"{m} values for {p} parameters: no degrees of freedom, the fit cannot be "
                    f"checked (chi^2 has no distribution); measure more angles")
    for i in range(p):
        for j in range(i + 1, p):
            c = corr[i, j]
            if math.isfinite(c) and abs(c) > corr_limit:
                diag.append(f"{fitted[i]} and {fitted[j]} are strongly correlated (rho = {c:+.4f}): "
                            f"the data determine a combination of them rather than each one; "
                            f"widen the angular range or hold one fixed")
    for q in fitted:
        v, e = vals[q], stderr[q]
        if math.isfinite(e) and v != 0 and e > 0.5 * abs(v):
            diag.append(f"{q} is poorly determined: {v:.4g} +- {e:.3g} ({100 * e / abs(v):.0f} %)")
        blo, bhi = BOUNDS[q]
        if v <= blo + 1e-6 * max(1.0, abs(blo)) or v >= bhi * (1 - 1e-9):
            diag.append(f"{q} = {v:.4g} sits on its bound [{blo:g}, {bhi:g}]: its standard error "
                        f"does not describe the uncertainty")
    return diag


def raise_or_warn(verdict, diag, strict, stacklevel=3):
    """An inadequate model and an ill-posed fit: raise (``strict``) or warn, in that order.  Too few
    geometries for the parameters is an ill-posed fit (:func:`~hyde_bsdf.fit.adequacy.too_few_geometries`)."""
    if verdict.cause == "too few geometries":
        diag = [verdict.message, *diag]
    elif not verdict.adequate:
        if strict:
            raise InadequateModelError(verdict.message)
        warnings.warn(verdict.message, InadequateModelWarning, stacklevel=stacklevel)
    if diag:
        text = "ill-posed fit: " + "; ".join(diag)
        if strict:
            raise IllPosedFitError(text)
        warnings.warn(text, IllPosedFitWarning, stacklevel=stacklevel)


def _adequacy(r, J, cov, ti, tr, ph, n_elements, chi2, dof, sigma_given):
    """The verdict (chi^2 with sigmas, the data's floor without) and the covariance: where the
    misfit is systematic, each error the larger of the classic and the cluster-robust one."""
    R = r.reshape(n_elements, -1)
    p = np.shape(J)[-1]
    verdict = (chi2_verdict(chi2, dof, R, ti, tr, ph, parameters=p) if sigma_given
               else floor_verdict(None, R[None], ti, tr, ph, parameters=p))
    if verdict.errors == "classic" or not np.all(np.isfinite(cov)):
        return verdict, cov
    th, td = half_angles(ti, tr, ph)
    return verdict, larger_errors(cov, cluster_covariance(J, r, np.tile(geometry_clusters(th, td), n_elements)))


def fit_measurements(meas: Measurements, **kwargs) -> FitResult:
    """:func:`fit_mueller` on a :class:`~hyde_bsdf.io.measurements.Measurements` (e.g. from a CSV):
    the normalized elements of one wavelength.  Measurements with M00 in 1/sr or at several
    wavelengths are refused (fit_mueller would drop M00 and fit one index to every wavelength):
    :func:`hyde_bsdf.fit.lab.fit_lab` fits them."""
    extra = ([f"{len(meas.wavelengths)} wavelengths"] if len(meas.wavelengths) > 1 else []) + \
        (["M00 in 1/sr"] if meas.m00 is not None else [])
    if extra:
        raise UsageError(f"{meas.source}: the measurements have {' and '.join(extra)}; fit_measurements fits one "
                         "wavelength's normalized elements and would drop them -- use hyde_bsdf.fit.lab.fit_lab")
    return fit_mueller(meas.theta_i, meas.theta_r, meas.phi, meas.values,
                       sigma=meas.uncertainty(), **kwargs)


def synthetic_measurements(theta_i, theta_r, phi, names=("M01", "M11", "M22", "M23"), *,
                           rms_slope, n, k, noise=0.03, n_samples=256, rng=None,
                           shadowing="vgroove", diffuse=True) -> Measurements:
    """Simulated measurements like the paper's Figs. 8-9 (means of ``n_samples`` samples).

    Each of ``n_samples`` single measurements of each normalized element is the model
    value plus Gaussian noise of standard deviation ``noise``; the result holds their
    mean, their sample standard deviation (the paper's +-1 sigma bars) and
    ``n_samples`` (so that the fit uses sigma / sqrt(n_samples), the error of the mean).
    Angles in radians; eta = n - jk.
    """
    if not (isinstance(n_samples, (int, np.integer)) and n_samples >= 2):
        raise UsageError(f"n_samples must be an integer >= 2, got {n_samples!r}")
    if not (math.isfinite(noise) and noise > 0):
        raise UsageError(f"noise must be > 0, got {noise!r}")
    rng = np.random.default_rng(rng)
    ti, tr, ph = (np.asarray(a, float).ravel() for a in np.broadcast_arrays(theta_i, theta_r, phi))
    truth = mueller_elements(ti, tr, ph, names, rms_slope=rms_slope, n=n, k=k,
                             shadowing=shadowing, diffuse=diffuse)
    values, sig = {}, {}
    for name in names:
        draws = truth[name][:, None] + noise * rng.standard_normal((ti.size, n_samples))
        values[name] = draws.mean(axis=1)
        sig[name] = draws.std(axis=1, ddof=1)
    return Measurements(theta_i=ti, theta_r=tr, phi=ph, values=values, sigma=sig,
                        n_samples=np.full(ti.size, float(n_samples)), source="<synthetic>")
