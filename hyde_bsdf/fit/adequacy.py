"""Model adequacy: does the fitted model describe the data, and what do its standard errors mean?

Every fit (:func:`hyde_bsdf.fit.fit_mueller`, :func:`hyde_bsdf.fit.fit_pbsdf`) carries a
:class:`Verdict`, judged against what the data themselves can show:

- **with error bars** (a CSV with sigmas): chi^2 and its p-value.  p < :data:`P_LIMIT` means the
  model and the sigmas together do not describe the data; the structure of the residuals says
  which (a smooth trend over the geometry: the model; plain scatter: the sigmas).
- **without error bars** (tables, a CSV without sigmas): the misfit is split into a *systematic*
  part (what the residuals share with their geometric neighbours: a trend over theta_h or theta_d)
  and *scatter* (what they do not: noise, interpolation, float32 rounding -- the data's own
  floor).  For residuals r_i and the mean s_i of the residuals of the :data:`NEIGHBOURS` nearest
  geometries (directions omega_i, omega_r), systematic^2 = mean(r_i s_i) (noise is uncorrelated
  between geometries, so it averages out of the product) and scatter^2 = mean(r^2) -
  systematic^2.  The model is inadequate when the systematic misfit is significant (z >
  :data:`Z_LIMIT` over the geometries) *and* above the tolerance (:data:`M00_TOLERANCE` relative
  in M00, :data:`ELEMENT_TOLERANCE` in the normalized elements): a misfit smaller than that is no
  reason to change the model, but it still biases the parameters.

Too few geometries: a fit is never adequate when its data have no more distinct geometries than the
parameters one wavelength's data must determine (a lobe through as many points as it has parameters
shows nothing about the model), nor, without error bars, fewer than :data:`MIN_GEOMETRIES` (each
residual is then judged against its :data:`NEIGHBOURS` neighbours': a lobe sampled at a handful of
points fits any roughness with an error bar of nothing -- one geometry of a table gave rms_slope
1.48 +- 7.8e-5).  The verdict says that the data cannot determine the parameters.

Standard errors: the usual ones, sqrt(diag((J^T J)^-1)) scaled by the residual scatter, assume the
misfit is independent noise.  When a systematic misfit dominates the scatter they are too small
(a smooth 0.2 % misfit of M00 over theta_h leaves the true rms_slope 70 of them away); then
:func:`cluster_covariance` -- a robust covariance, the delete-one-cluster jackknife over clusters
of neighbouring geometries (theta_h x theta_d bins), so that residuals that move together count
as one -- is used where it is larger, and the verdict says so (``errors = "robust"``).
When the model is inadequate no error covers the model error: the verdict says the errors are
lower bounds (``errors = "lower bounds"``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hyde_bsdf.errors import RejectedResult

__all__ = ["Verdict", "InadequateModelWarning", "InadequateModelError", "ERRORS_NOTE", "P_LIMIT",
           "M00_TOLERANCE", "ELEMENT_TOLERANCE", "Z_LIMIT", "NEIGHBOURS",
           "half_angles", "neighbour_index", "residual_structure", "angle_trends", "geometry_clusters", "cluster_covariance",
           "correlation", "larger_errors", "MIN_GEOMETRIES", "too_few_geometries", "MODEL_ADVICE", "without_advice",
           "chi2_verdict", "floor_verdict", "birge_scaling", "blame_fixed_parameters", "SIGMAS_OR_MODEL", "json_number",
           "chi2_sf", "chi2_cdf", "chi2_isf"]

#: chi^2 tail probability below which a fit with error bars is inadequate
P_LIMIT = 1e-3
#: systematic rms misfit of M00 (relative) above which a table fit is inadequate
M00_TOLERANCE = 0.01
#: systematic rms misfit of the normalized elements M_jk/M00 above which a fit is inadequate
ELEMENT_TOLERANCE = 0.005
#: a systematic misfit counts only when it is this many standard errors above 0
Z_LIMIT = 5.0
#: a systematic misfit below this (relative) is the float32 rounding of a stored table
FLOAT32_FLOOR = 1e-6
#: neighbours whose residuals define the systematic part
NEIGHBOURS = 8
#: what an inadequate verdict of one fixed model advises (the command line says ``--model auto``:
#: hyde_bsdf.app.flags); model selection, which tried them all, drops it (:func:`without_advice`)
MODEL_ADVICE = "; try `select_model`"
#: fewest distinct geometries a verdict without error bars can be "adequate" at (module docstring)
MIN_GEOMETRIES = NEIGHBOURS + 2
#: quantile bins of theta_h and of theta_d for the trends
BINS = 4
#: ... and for the clusters of the robust covariance: 2 x 2 = 4 clusters (low/high theta_h x
#: theta_d).  Fewer, larger clusters are more conservative: a smooth 0.2 % misfit of M00 leaves
#: the truth 1.1 robust errors away with 4 clusters, 1.6 with 9, 2.2 with 16, 71 classic ones
CLUSTER_BINS = 2


class InadequateModelWarning(UserWarning):
    """The fitted model does not describe the data (the message gives the figure and the cause)."""


class InadequateModelError(RejectedResult):
    """Raised instead of :class:`InadequateModelWarning` by a fit with ``strict=True``."""


#: what the printed standard errors mean, by Verdict.errors
ERRORS_NOTE = {
    "classic": "linearized, sqrt(diag((J^T J)^-1)) (scaled by the residual scatter where the data have no "
               "sigmas); they hold because the misfit is scatter, not a trend",
    "robust": "robust (cluster sandwich over neighbouring geometries), as the misfit is systematic",
    "lower bounds": "LOWER BOUNDS: the model does not describe the table, and no error covers that",
}


@dataclass
class Verdict:
    """Whether the model describes the data; figures as fractions (0.01 = 1 %)."""

    adequate: bool
    test: str                       # "chi2" (error bars given) or "floor" (none: a table)
    errors: str                     # "classic", "robust" or "lower bounds"
    figures: dict = field(default_factory=dict)
    message: str = ""               # the WARNING text when inadequate, else a one-line statement
    cause: str = ""

    def line(self) -> str:
        """One line for a summary: "adequate: ..." or "INADEQUATE: ..."."""
        return ("adequate: " if self.adequate else "INADEQUATE: ") + self.message


def half_angles(theta_i, theta_r, phi):
    """theta_h (half vector from the normal) and theta_d (half vector from omega_i), radians."""
    oi, orr = _directions(theta_i, theta_r, phi)
    h = oi + orr
    h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
    return np.arccos(np.clip(h[:, 2], -1, 1)), np.arccos(np.clip(np.einsum("ij,ij->i", h, oi), -1, 1))


def _directions(theta_i, theta_r, phi):
    ti, tr, ph = (np.asarray(a, float).ravel() for a in (theta_i, theta_r, phi))
    oi = np.stack([np.sin(ti), np.zeros_like(ti), np.cos(ti)], -1)
    orr = np.stack([np.sin(tr) * np.cos(ph), np.sin(tr) * np.sin(ph), np.cos(tr)], -1)
    return oi, orr


def neighbour_index(theta_i, theta_r, phi, k=NEIGHBOURS):
    """(N, k) indices of each geometry's k nearest geometries (by the directions omega_i, omega_r);
    None for fewer than 2 geometries."""
    from scipy.spatial import cKDTree

    pts = np.concatenate(_directions(theta_i, theta_r, phi), axis=1)
    k = min(k, pts.shape[0] - 1)
    if k < 1:
        return None
    return cKDTree(pts).query(pts, k=k + 1)[1][:, 1:]


def residual_structure(r, neighbours):
    """Systematic and scatter rms of residuals ``r`` (B, ..., N): B bands, N geometries.

    The systematic part is what a residual shares with the residuals of the same geometry in the
    other bands (B >= 2) or of its neighbouring geometries (``neighbours`` (N, k) indices; None:
    too few geometries): systematic^2 = mean(r_i s_i), s_i their mean, whichever is larger; z is
    that mean in units of its standard error (noise alone gives z ~ N(0, 1))."""
    r = np.asarray(r, float)
    total = float(np.sqrt(np.mean(r * r)))
    best = (0.0, 0.0)
    partners = []
    if r.shape[0] >= 2:
        partners.append((r.sum(axis=0, keepdims=True) - r) / (r.shape[0] - 1))
    if neighbours is not None:
        partners.append(r[..., neighbours].mean(axis=-1))
    for s in partners:
        prod = (r * s).reshape(-1)
        mean = float(prod.mean())
        se = float(prod.std()) / math.sqrt(prod.size)
        z = mean / se if se > 0 else (math.inf if mean > 0 else 0.0)
        if mean > best[0]:
            best = (mean, z)
    sys2, z = best
    return {"rms": total, "systematic": math.sqrt(sys2), "scatter": math.sqrt(max(total ** 2 - sys2, 0.0)), "z": z}


def angle_trends(r, theta_h, theta_d, bins=BINS):
    """Range (max - min) of the mean residual over quantile bins of theta_h and of theta_d;
    ``r`` (..., N), averaged over the leading axes first."""
    r = np.asarray(r, float).reshape(-1, np.shape(theta_h)[0]).mean(axis=0)
    out = {}
    for name, a in (("theta_h", theta_h), ("theta_d", theta_d)):
        edges = np.quantile(a, np.linspace(0, 1, bins + 1)[1:-1])
        lab = np.searchsorted(edges, a)
        means = [r[lab == b].mean() for b in range(bins) if np.any(lab == b)]
        out[name] = float(max(means) - min(means)) if means else 0.0
    return out


def geometry_clusters(theta_h, theta_d, bins=CLUSTER_BINS):
    """Cluster label per geometry: quantile bins of theta_h x theta_d (each geometry its own cluster
    when there are no more than bins^2 geometries)."""
    n = np.shape(theta_h)[0]
    if n <= bins * bins:
        return np.arange(n)
    lab = []
    for a in (theta_h, theta_d):
        edges = np.quantile(a, np.linspace(0, 1, bins + 1)[1:-1])
        lab.append(np.searchsorted(edges, a))
    return lab[0] * bins + lab[1]


def cluster_covariance(J, r, labels):
    """Cluster-robust covariance of a least-squares fit, as the delete-one-cluster jackknife
    (CR3): (G-1)/G sum_g (d_g - mean d)(d_g - mean d)^T with d_g = (J^T J - J_g^T J_g)^-1 J_g^T r_g
    the linearized change of the parameters when cluster g is left out.  ``labels``: one cluster
    label per row of J.  Unlike the plain sandwich it weighs an influential cluster by its
    leverage, which is where a systematic misfit pulls the fit.  None when J^T J is singular or
    there are fewer than 2 clusters."""
    J, r = np.asarray(J, float), np.asarray(r, float)
    uniq, inv = np.unique(labels, return_inverse=True)
    G, p = uniq.size, J.shape[1]
    if G < 2:
        return None
    H = J.T @ J
    D = np.empty((G, p))
    order = np.argsort(inv, kind="stable")
    bounds = np.searchsorted(inv[order], np.arange(G + 1))
    try:
        for g in range(G):
            rows = order[bounds[g]:bounds[g + 1]]
            Jg = J[rows]
            D[g] = np.linalg.solve(H - Jg.T @ Jg, Jg.T @ r[rows])
    except np.linalg.LinAlgError:
        return None
    D -= D.mean(axis=0)
    return (G - 1) / G * (D.T @ D)


def correlation(cov):
    """The correlation matrix of a covariance matrix."""
    se = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    return cov / np.outer(se, se)


def larger_errors(cov, robust):
    """``cov`` with each standard error the larger of its own and ``robust``'s (None: ``cov``);
    the correlations stay ``cov``'s (the Jacobian's: what the data can separate)."""
    if robust is None:
        return cov
    se = np.sqrt(np.maximum(np.diag(cov), np.diag(robust)))
    return np.outer(se, se) * correlation(cov)


def _cause(trends, elements_bad, m00_bad):
    worst = max(trends, key=trends.get) if trends else "theta_d"
    if m00_bad and worst == "theta_d":
        return ("the diffuse term or the shadowing does not fit (the residuals trend with theta_d, "
                "towards grazing angles)")
    if m00_bad:
        return "the lobe's shape (roughness, shadowing or diffuse term) does not fit (the residuals trend with theta_h)"
    if elements_bad:
        return "the polarization does not fit (the index, or the diffuse term's depolarization)"
    return "the model does not fit"


def without_advice(verdict: Verdict) -> Verdict:
    """``verdict`` without :data:`MODEL_ADVICE` (for a model chosen among all of them)."""
    verdict.message = verdict.message.replace(MODEL_ADVICE, "")
    return verdict


def too_few_geometries(theta_i, theta_r, phi, parameters: int = 0, test: str = "floor") -> Verdict | None:
    """An inadequate Verdict when the data have no more distinct geometries than ``parameters`` (what one
    wavelength's data must determine) or, for the ``"floor"`` test (no error bars), fewer than
    :data:`MIN_GEOMETRIES` (module docstring); None when there are enough."""
    geometries = np.unique(np.round(np.stack(np.broadcast_arrays(theta_i, theta_r, phi), axis=-1), 9), axis=0)
    n = len(geometries)
    need = max(2, int(parameters) + 1, MIN_GEOMETRIES if test == "floor" else 0)
    if n >= need:
        return None
    what = f"the {parameters} fitted parameter(s)" if parameters else "the parameters"
    return Verdict(False, test, "lower bounds", {"geometries": n, "needed": need},
                   f"{n} distinct geometr{'y' if n == 1 else 'ies'} cannot determine {what} nor show whether the "
                   f"model describes the data (at least {need} needed{'' if test != 'floor' else ' without sigma'}): "
                   "the values and their errors are not measurements; add geometries", "too few geometries")


def chi2_sf(chi2, dof):
    """P(X >= chi2) for X chi-square distributed with ``dof`` > 0 degrees of freedom: the values of
    ``scipy.stats.chi2.sf`` (1 at chi2 <= 0), from the function it calls, ``scipy.special.chdtrc`` --
    importing ``scipy.stats`` costs 0.7 CPU s and 40,000 objects per process."""
    from scipy.special import chdtrc

    x = np.asarray(chi2, float)
    return np.where(x <= 0.0, 1.0, chdtrc(dof, np.maximum(x, 0.0)))[()]


def chi2_cdf(chi2, dof):
    """P(X <= chi2) (``scipy.stats.chi2.cdf``'s values, 0 at chi2 <= 0; see :func:`chi2_sf`)."""
    from scipy.special import chdtr

    x = np.asarray(chi2, float)
    return np.where(x <= 0.0, 0.0, chdtr(dof, np.maximum(x, 0.0)))[()]


def chi2_isf(p, dof):
    """The chi2 that X exceeds with probability ``p`` in (0, 1) (``scipy.stats.chi2.isf``'s values; see
    :func:`chi2_sf`)."""
    from scipy.special import chdtri

    return chdtri(dof, p)


def chi2_verdict(chi2, dof, r, theta_i, theta_r, phi, neighbours=None, parameters: int = 0):
    """Verdict from chi^2 with error bars; ``r`` (E, N) weighted residuals of E elements.
    ``neighbours``: the geometries' neighbour index when already known (:func:`neighbour_index`);
    ``parameters``: what one wavelength's data must determine (:func:`too_few_geometries`)."""
    few = too_few_geometries(theta_i, theta_r, phi, parameters, "chi2")
    if few is not None:
        return few
    if dof <= 0:
        return Verdict(False, "chi2", "lower bounds", {"chi2": chi2, "dof": dof},
                       "no degrees of freedom: the fit cannot be checked; add data", "no degrees of freedom")
    p = float(chi2_sf(chi2, dof))
    red = chi2 / dof
    nb = neighbour_index(theta_i, theta_r, phi) if neighbours is None else neighbours
    st = residual_structure(np.asarray(r, float)[None], nb)   # one band
    th, td = half_angles(theta_i, theta_r, phi)
    trends = angle_trends(r, th, td)
    figs = {"chi2": chi2, "dof": dof, "reduced_chi2": red, "p_value": p, "systematic_sigmas": st["systematic"],
            "scatter_sigmas": st["scatter"], "z": st["z"], **{f"trend_{k}": v for k, v in trends.items()}}
    if p >= P_LIMIT:
        return Verdict(True, "chi2", "classic", figs, f"chi^2 = {chi2:.4g} for {dof} dof (p = {p:.3g})")
    structured = st["z"] > 3.0 and st["systematic"] > st["scatter"] / 2     # (only names the likely cause)
    cause = (_cause(trends, True, False) + f"; systematic residual {st['systematic']:.3g} sigma against scatter "
             f"{st['scatter']:.3g} sigma") if structured else \
        (f"the residuals are scatter without a trend ({st['scatter']:.3g} sigma rms): the sigmas underestimate "
         "the noise")
    msg = (f"reduced chi^2 = {red:.4g} (chi^2 = {chi2:.4g} for {dof} dof, p = {p:.3g}): {cause}"
           + ("" if structured else "; check the sigmas") + MODEL_ADVICE)
    return Verdict(False, "chi2", "lower bounds", figs, msg, cause)


def floor_verdict(m00, elements, theta_i, theta_r, phi, neighbours=None, parameters: int = 0):
    """Verdict without error bars.  ``m00``: log residuals of M00 (B, N) (None: not fitted, as
    for a CSV); ``elements``: residuals of the normalized elements (B, E, N); B bands, N geometries.
    ``neighbours``: the geometries' neighbour index when already known (:func:`neighbour_index`);
    ``parameters``: what one wavelength's data must determine (:func:`too_few_geometries`)."""
    few = too_few_geometries(theta_i, theta_r, phi, parameters)
    if few is not None:
        return few
    nb = neighbour_index(theta_i, theta_r, phi) if neighbours is None else neighbours
    th, td = half_angles(theta_i, theta_r, phi)
    figs, bad, trends = {}, [], {}
    parts = ([("M00", m00, M00_TOLERANCE)] if m00 is not None else []) + [("elements", elements, ELEMENT_TOLERANCE)]
    systematic_dominates, unproven = False, []
    for name, r, tol in parts:
        st = residual_structure(r, nb)
        figs.update({f"{name}_{k}": v for k, v in st.items()})
        if st["systematic"] > max(st["scatter"], FLOAT32_FLOOR) and st["z"] > Z_LIMIT:
            systematic_dominates = True
        if st["systematic"] > tol and st["z"] > Z_LIMIT:
            bad.append(name)
            trends = trends or angle_trends(r, th, td)
        elif st["systematic"] > tol:
            unproven.append(f"{name} (z = {st['z']:.2g})")
    if not bad:
        what = "; ".join(_describe(name, figs) for name, _, _ in parts)
        errors = "robust" if systematic_dominates else "classic"
        head = (f"not shown inadequate: the systematic misfit of {', '.join(unproven)} exceeds the tolerance but "
                f"{np.shape(theta_i)[0]} geometries cannot show it is significant ({what})" if unproven else
                f"systematic misfit within tolerance ({what})")
        return Verdict(True, "floor", errors, figs, head +
                       ("; it exceeds the scatter, so the standard errors are robust (sandwich)" if errors == "robust" else ""))
    cause = _cause(trends, "elements" in bad, "M00" in bad)
    lead = bad[0]
    pct = (lambda v: f"{100 * v:.3g} %") if lead == "M00" else (lambda v: f"{v:.3g}")
    msg = (f"{lead} misfit {pct(figs[f'{lead}_rms'])} rms (systematic {pct(figs[f'{lead}_systematic'])}, the data's "
           f"floor {pct(figs[f'{lead}_scatter'])}; tolerance {pct(M00_TOLERANCE if lead == 'M00' else ELEMENT_TOLERANCE)}): "
           f"{cause}" + MODEL_ADVICE)
    figs.update({f"trend_{k}": v for k, v in trends.items()})
    return Verdict(False, "floor", "lower bounds", figs, msg, cause)


def _describe(name, figs):
    if name == "M00":
        return (f"M00 {100 * figs['M00_systematic']:.3g} % systematic, {100 * figs['M00_scatter']:.3g} % scatter")
    return f"elements {figs['elements_systematic']:.3g} systematic, {figs['elements_scatter']:.3g} scatter"


#: what a reduced chi^2 far above 1 says by itself: one of the two is wrong, the test cannot tell
#: which -- unless a parameter held fixed explains it (:func:`blame_fixed_parameters`)
SIGMAS_OR_MODEL = "the sigmas underestimate the scatter, or the model does not describe the data"


def birge_scaling(chi2, dof, cov, notes):
    """With sigmas: a reduced chi^2 far above 1 (p < :data:`P_LIMIT`) scales the errors up by the
    Birge ratio sqrt(chi^2 / dof) (never down); far from 1 either way adds a note to ``notes``.
    Returns (scale, covariance)."""
    red = chi2 / dof
    if chi2_sf(chi2, dof) < P_LIMIT:
        scale = math.sqrt(red)      # the Birge ratio: errors as large as the scatter says
        if red > 2.0:
            notes.append(f"reduced chi^2 = {red:.4g} is far above 1 (dof = {dof}): {SIGMAS_OR_MODEL}; the "
                         f"standard errors are scaled by sqrt(chi^2_red) = {scale:.3g}")
        return scale, cov * red
    if chi2_cdf(chi2, dof) < P_LIMIT and red < 0.5:
        # never scaled down: noiseless or over-cautious sigmas must not shrink the errors to 0
        notes.append(f"reduced chi^2 = {red:.4g} is far below 1 (dof = {dof}): the sigmas overestimate the "
                     "scatter, or the rows are not independent measurements; the standard errors follow the "
                     "given sigmas and may be too large")
    return 1.0, cov


def blame_fixed_parameters(verdict: Verdict, notes: list, chi2, dof, free, held: str, freed: str) -> bool:
    """A misfit with parameters held fixed, against the same model with every parameter fitted
    (``free``: its (chi2, dof, adequate)).  When that one describes the data, or fits significantly
    better (chi^2 difference test, p < :data:`P_LIMIT`), the fixed parameters cause the misfit, not
    the sigmas: ``verdict``'s cause and message, and the sigma-or-model note among ``notes``
    (:func:`birge_scaling`), are rewritten to name them (``held``: "rms_slope = 0.3"; ``freed``: the
    values they take when fitted).  Returns whether they were."""
    free_chi2, free_dof, free_adequate = free
    gained = dof - free_dof
    if not (free_adequate or (gained > 0 and chi2 > free_chi2 and chi2_sf(chi2 - free_chi2, gained) < P_LIMIT)):
        return False
    fixed = f"the parameter(s) held fixed ({held}) cause the misfit, not the sigmas"
    verdict.cause = (f"{fixed}: with them fitted the model {'describes' if free_adequate else 'fits significantly better'}"
                     f" the data (chi^2 = {free_chi2:.4g} for {free_dof} dof; {freed})")
    red = f"reduced chi^2 = {chi2 / dof:.4g} (chi^2 = {chi2:.4g} for {dof} dof)" if dof > 0 else f"chi^2 = {chi2:.4g}"
    verdict.message = f"{red}: {verdict.cause}; fit them"
    notes[:] = [n.replace(SIGMAS_OR_MODEL, fixed) for n in notes]
    return True


def json_number(x):
    """A number as a fit's JSON result carries it: a float, None where it is not finite."""
    x = float(x)
    return x if math.isfinite(x) else None
