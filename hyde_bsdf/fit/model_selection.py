"""Model selection (``--model auto``): the simplest model that describes the data.

Candidates: shadowing {none, smith, vgroove} x diffuse {none, paper, reciprocal} (reciprocal needs
shadowing, so none x reciprocal is listed as undefined: 8 models), plus k = 0 (a dielectric) for
the best models where the data allow one (their fitted k below :data:`DIELECTRIC_K`).

Size of a model: its free parameters (a table's: on the middle band, rms_slope, n, k) plus one for
each term it adds (a shadowing function, a diffuse term); the terms have no free parameters of
their own, so the information criterion alone cannot tell them apart.  Rule: among the *adequate* models (:mod:`hyde_bsdf.fit.adequacy`) the
smallest, ties broken by the Bayesian information criterion

    BIC = chi^2 + p ln m            (data with sigmas; m values, p free parameters)
    BIC = m ln(RSS / m) + p ln m    (tables and data without sigmas, with weights common to all models)

When no model is adequate the lowest BIC is chosen and the verdict says so.

Speed (tables): every model is first fitted on the middle band and :data:`SCREEN_ROWS` geometries
(the *screen*), each starting from the best already-fitted neighbouring model (one term changed)
and two fixed starts.  On the screen a model is adequate when its misfit in excess of the best
screened model's is within the tolerance (one band and a few hundred geometries are too few for the
verdict's own tests); the rule above picks one, and only that model is fitted jointly on every band
and geometry (:func:`hyde_bsdf.fit.fit_pbsdf` from the screen's values) and its verdict made on all
the data; if it fails the next candidate is tried (at most :data:`MAX_FULL_FITS`).  With error bars
(CSV) every model is fitted fully, warm-started the same way.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from hyde_bsdf.fit.adequacy import (ELEMENT_TOLERANCE, M00_TOLERANCE, InadequateModelWarning, json_number,
                                    without_advice)
from hyde_bsdf.model.terms import DIFFUSE_TERMS, SHADOWING_TERMS, allowed, model_size

__all__ = ["CANDIDATES", "ModelRow", "ModelSelection", "select_model", "select_model_pbsdf"]

#: every combination of the terms of model/terms.py, simplest first (each record's rank); a pair
#: the terms' rule refuses (none x reciprocal: no shadowing, rho > 1) is listed as undefined.  A
#: term with parameters of its own (the Lambertian albedo) is fitted by :mod:`hyde_bsdf.fit.lab`,
#: not here
CANDIDATES = tuple((s.name, d.name) for s in sorted(SHADOWING_TERMS, key=lambda t: t.rank)
                   for d in sorted(DIFFUSE_TERMS, key=lambda t: t.rank) if not d.parameters)
#: a k = 0 variant is tried for models whose fitted k (middle band) is below this
DIELECTRIC_K = 0.5
#: geometries of the screen (tables)
SCREEN_ROWS = 600
#: fixed starts (n, k) tried besides the neighbour's solution
SCREEN_STARTS = ((1.5, 0.5), (0.3, 3.0))
#: most full fits tried before giving up on the screen's order
MAX_FULL_FITS = 3




@dataclass
class ModelRow:
    """One candidate: its fit on the screen (tables) or the data (CSV)."""

    shadowing: str
    diffuse: str
    dielectric: bool
    params: dict                 # rms_slope, n, k (middle band for a table's screen)
    n_params: int
    size: int
    bic: float
    misfit: dict                 # "M00" (relative rms, tables) and "elements" (rms), or "reduced_chi2"
    adequate: bool
    stage: str                   # "screen", "full" or "undefined"
    note: str = ""

    @property
    def label(self) -> str:
        return f"{self.shadowing}/{self.diffuse}" + (" k=0" if self.dielectric else "")


@dataclass
class ModelSelection:
    """The table of candidates, the choice and why; ``result`` is the chosen model's full fit."""

    rows: list
    chosen: int
    reason: str
    result: object
    criterion: str = "BIC"
    notes: list = field(default_factory=list)

    @property
    def choice(self) -> ModelRow:
        return self.rows[self.chosen]

    def table(self) -> str:
        head = (f"  {'model':22s} {'params':>6s} {'size':>4s} {'BIC':>12s} {'misfit':>22s} {'rms_slope':>9s} "
                f"{'n':>8s} {'k':>8s}  verdict")
        out = [head]
        for i, r in enumerate(self.rows):
            if r.stage == "undefined":
                out.append(f"  {r.label:22s} {'':>6s} {'':>4s} {'':>12s} {'':>22s} {'':>9s} {'':>8s} {'':>8s}  "
                           f"undefined ({r.note})")
                continue
            mis = (f"chi2_red {r.misfit['reduced_chi2']:.3g}" if "reduced_chi2" in r.misfit else
                   f"M00 {100 * r.misfit.get('M00', float('nan')):.3g} %, el {r.misfit['elements']:.2g}")
            tag = ("adequate" if r.adequate else "inadequate") + f" ({r.stage})" + (" <- chosen" if i == self.chosen else "")
            out.append(f"  {r.label:22s} {r.n_params:6d} {r.size:4d} {r.bic:12.6g} {mis:>22s} "
                       f"{r.params['rms_slope']:9.4g} {r.params['n']:8.4g} {r.params['k']:8.4g}  {tag}")
        return "\n".join(out)

    def to_dict(self) -> dict:
        """The chosen fit's machine-readable result (its ``to_dict``: a table fit's,
        :meth:`hyde_bsdf.fit.pbsdf_fit.PbsdfFitResult.to_dict`) with this table of candidates as its
        ``models``: shadowing, diffuse, dielectric, free parameters, size, BIC, misfit, adequate, the
        stage its verdict was made at ("screen", "full" or "undefined"), chosen, and the values."""
        rows = [{"shadowing": r.shadowing, "diffuse": r.diffuse, "dielectric": r.dielectric,
                 "free_parameters": r.n_params, "size": r.size, "bic": json_number(r.bic),
                 "misfit": {q: json_number(x) for q, x in r.misfit.items()}, "adequate": bool(r.adequate),
                 "stage": r.stage, "chosen": i == self.chosen, "values": {q: json_number(x) for q, x in r.params.items()}}
                for i, r in enumerate(self.rows)]
        return self.result.to_dict(models=rows)

    def summary(self) -> str:
        return "\n".join([f"model selection ({len([r for r in self.rows if r.stage != 'undefined'])} models; "
                          f"information criterion {self.criterion}; size = free parameters + terms):",
                          self.table(), f"  chosen: {self.choice.label} -- {self.reason}"] +
                         [f"  note: {n}" for n in self.notes])


def _choose(rows):
    """Index of the smallest adequate model (ties: lowest BIC), else the lowest BIC; and why."""
    ok = [i for i, r in enumerate(rows) if r.stage != "undefined" and r.adequate]
    if ok:
        i = min(ok, key=lambda j: (rows[j].size, rows[j].bic))
        bigger = [rows[j].label for j in ok if rows[j].size > rows[i].size]
        return i, (f"the smallest adequate model (size {rows[i].size}" +
                   (f"; also adequate but larger: {', '.join(bigger)}" if bigger else "") +
                   "; among equal sizes the lowest BIC)")
    live = [i for i, r in enumerate(rows) if r.stage != "undefined"]
    i = min(live, key=lambda j: rows[j].bic)
    return i, "NO model is adequate; this one has the lowest BIC, and its errors are lower bounds"


def _order(start=("vgroove", "paper")):
    """Candidates in an order where each (after the first) has an already-fitted neighbour."""
    todo = [c for c in CANDIDATES if allowed(*c) and c != start]
    done = [start]
    while todo:
        nxt = next(c for c in todo if any((c[0] == d[0]) + (c[1] == d[1]) == 1 for d in done))
        todo.remove(nxt)
        done.append(nxt)
    return done


def _neighbour_start(model, fitted):
    """Parameters of the best (lowest BIC) fitted model differing from ``model`` in one term."""
    near = [r for r in fitted if (r.shadowing == model[0]) + (r.diffuse == model[1]) == 1 and not r.dielectric]
    return min(near, key=lambda r: r.bic).params if near else None


def _undefined_rows():
    return [ModelRow(s, d, False, {}, 0, 0, math.inf, {}, False, "undefined",
                     f"{d} diffuse needs a shadowing term with rho <= 1") for s, d in CANDIDATES if not allowed(s, d)]


def _bic_weighted(rss, m, p):
    return m * math.log(max(rss, 1e-300) / m) + p * math.log(m)


# ---------------------------------------------------------------------------------------------
# CSV (Mueller-matrix measurements)

def select_model(theta_i, theta_r, phi, measured, *, sigma=None, fit=None, rms_slope=0.3, n0=None, k0=None,
                 strict=False, **kwargs) -> ModelSelection:
    """Fit every candidate to normalized Mueller measurements (as :func:`hyde_bsdf.fit.fit_mueller`,
    same arguments but no shadowing/diffuse; ``fit`` None: what each candidate's data determine) and
    choose; returns a :class:`ModelSelection`.

    More than :data:`CSV_SCREEN_ROWS` values per element: the candidates are fitted to that many
    (a fixed random subset), and only the chosen one to all the data."""
    from hyde_bsdf.fit.mueller_fit import _check_fit_names, fit_mueller

    fitted_names = _check_fit_names(fit)
    names = lambda model: _check_fit_names(None, model[1]) if fit is None else fitted_names   # noqa: E731
    full = (theta_i, theta_r, phi, measured, sigma)
    data, screened = _csv_subset(full)
    rows, results = [], []
    for model in _order():
        start = _neighbour_start(model, rows)
        row, res = _csv_candidate(model, False, names(model), start, rms_slope, n0, k0, data, kwargs, fit_mueller)
        rows.append(row)
        results.append(res)
    best_k = min(rows, key=lambda r: r.bic).params["k"]
    if "k" in fitted_names and best_k < DIELECTRIC_K:
        for model in sorted({(r.shadowing, r.diffuse) for r in sorted(rows, key=lambda r: r.bic)[:3]}):
            start = next(r.params for r in rows if (r.shadowing, r.diffuse) == model)
            row, res = _csv_candidate(model, True, tuple(q for q in names(model) if q != "k"), start, rms_slope,
                                      n0, 0.0, data, kwargs, fit_mueller)
            rows.append(row)
            results.append(res)
    i, why = _choose(rows)
    result = results[i]
    if screened:
        r = rows[i]
        rows[i], result = _csv_candidate((r.shadowing, r.diffuse), r.dielectric, result.fitted, r.params, rms_slope,
                                         n0, 0.0 if r.dielectric else k0, full, kwargs, fit_mueller)
        rows[i].note = "fitted to all the data; the others to a subset"
    sel = ModelSelection(rows + _undefined_rows(), i, why, result)
    _finish(sel, strict)
    return sel


#: above this many values per element, the candidates are fitted to a fixed random subset
CSV_SCREEN_ROWS = 4000


def _csv_subset(data):
    """``data`` (theta_i, theta_r, phi, measured, sigma) flattened to at most CSV_SCREEN_ROWS rows
    (fixed seed), and whether it was cut."""
    ti, tr, ph, measured, sigma = data
    arrays = [np.asarray(a, float) for a in (ti, tr, ph)] + [np.asarray(v, float) for v in measured.values()]
    if sigma is not None:
        arrays += [np.asarray(sigma[k], float) for k in measured]
    try:
        flat = [a.ravel() for a in np.broadcast_arrays(*arrays)]
    except ValueError:
        return data, False          # fit_mueller names the mismatch
    if flat[0].size <= CSV_SCREEN_ROWS:
        return data, False
    keep = np.sort(np.random.default_rng(0).choice(flat[0].size, CSV_SCREEN_ROWS, replace=False))
    flat = [a[keep] for a in flat]
    names = list(measured)
    values = dict(zip(names, flat[3:3 + len(names)]))
    sig = dict(zip(names, flat[3 + len(names):])) if sigma is not None else None
    return (flat[0], flat[1], flat[2], values, sig), True


def _csv_candidate(model, dielectric, names, start, rms_slope, n0, k0, data, kwargs, fit_mueller):
    ti, tr, ph, measured, sigma = data
    if start is not None:
        rms_slope = start["rms_slope"] if "rms_slope" in names else rms_slope
        n0 = start["n"] if "n" in names else n0
        k0 = start["k"] if "k" in names else k0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = fit_mueller(ti, tr, ph, measured, sigma=sigma, fit=names, rms_slope=rms_slope, n0=n0,
                          k0=0.0 if dielectric else k0, shadowing=model[0], diffuse=model[1], **kwargs)
    m, p = res.n_data, len(res.fitted)
    if res.sigma_given:
        bic, misfit = res.chi2 + p * math.log(m), {"reduced_chi2": res.reduced_chi2}
    else:
        bic, misfit = _bic_weighted(res.chi2, m, p), {"elements": math.sqrt(res.chi2 / m)}
    row = ModelRow(model[0], model[1], dielectric, dict(res.params), p, model_size(*model, p), bic, misfit,
                   bool(res.verdict.adequate), "full")
    return row, res


def _finish(sel, strict):
    res = sel.result
    without_advice(res.verdict)                  # every model was tried: no "try --model auto"
    if not res.verdict.adequate:
        if strict:
            from hyde_bsdf.fit.adequacy import InadequateModelError
            raise InadequateModelError(f"no candidate model is adequate; the best ({sel.choice.label}): "
                                       f"{res.verdict.message}")
        warnings.warn(f"no candidate model is adequate; the best ({sel.choice.label}): {res.verdict.message}",
                      InadequateModelWarning, stacklevel=3)


# ---------------------------------------------------------------------------------------------
# measured_polarized tables

def _screen(data, rows, band, model, dielectric, fit, fixed, starts):
    """One candidate on the screen: the best of ``starts`` (dicts rms_slope, n, k) by weighted cost."""
    from scipy.optimize import least_squares

    from hyde_bsdf.fit.pbsdf_fit import _bounds, _Problem

    names = [q for q in ("n", "k") if q in fit and not (dielectric and q == "k")]
    free = [(q, band) for q in names] + (["rms_slope"] if "rms_slope" in fit else [])
    best = None
    for st in starts:
        vals = {("n", band): st["n"], ("k", band): 0.0 if dielectric else st["k"], "rms_slope": st["rms_slope"]}
        vals.update({(q, band): v for q, v in fixed.items() if v is not None and (q, band) not in free})
        prob = _Problem(data, [band], rows, free, {p: v for p, v in vals.items() if p not in free},
                        model[0], model[1], 0.05, 0.01, lambda r: None)
        lo, hi = _bounds(free)
        x0 = np.clip([vals[p] for p in free], lo + 1e-9, hi - 1e-9)
        res = least_squares(prob, x0, jac=lambda x, pr=prob: pr.jac(x, hi), bounds=(lo, hi), method="trf",
                            x_scale="jac", max_nfev=40 * len(free), xtol=1e-10, ftol=1e-10, gtol=1e-10)
        if best is None or res.cost < best[0].cost:
            best = (res, prob)
    res, prob = best
    v = prob.values(res.x)
    r00, rel = prob.parts(res.x)
    m, p = res.fun.size, len(free)
    return ModelRow(model[0], model[1], dielectric, {"rms_slope": v["rms_slope"], "n": v[("n", band)],
                    "k": v[("k", band)]}, p, model_size(*model, p), _bic_weighted(2 * res.cost, m, p),
                    {"M00": float(np.sqrt(np.mean(r00 ** 2))), "elements": float(np.sqrt(np.mean(rel ** 2)))},
                    False, "screen")


def select_model_pbsdf(data, *, fit=("n", "k", "rms_slope"), rms_slope=0.3, n0=None, k0=None, strict=False,
                       progress=None, **sample_options) -> ModelSelection:
    """:func:`hyde_bsdf.fit.fit_pbsdf` over every candidate model, and the choice (module docstring).

    ``data``, ``fit``, ``rms_slope``, ``n0``, ``k0``, ``progress`` and ``sample_options`` as for
    :func:`~hyde_bsdf.fit.fit_pbsdf`; ``strict``: raise
    :class:`~hyde_bsdf.fit.adequacy.InadequateModelError` when no model is adequate.  Returns a
    :class:`ModelSelection` whose ``result`` is the chosen model's full
    :class:`~hyde_bsdf.fit.pbsdf_fit.PbsdfFitResult`.
    """
    from hyde_bsdf.fit.pbsdf_samples import PbsdfSamples, pbsdf_samples
    from hyde_bsdf.fit.pbsdf_fit import STARTS, _check

    fit = _check(fit, rms_slope, n0, k0, "vgroove", "paper")
    if not isinstance(data, PbsdfSamples):
        data = pbsdf_samples(data, progress=progress or False, **sample_options)
    band = data.wavelengths.size // 2
    rows_all = np.arange(len(data))
    screen = rows_all if rows_all.size <= SCREEN_ROWS else \
        np.sort(np.random.default_rng(0).choice(rows_all, SCREEN_ROWS, replace=False))
    fixed = {"n": n0, "k": k0}
    first = [{"rms_slope": rms_slope, "n": n0 if n0 is not None else a, "k": k0 if k0 is not None else b}
             for a in STARTS["n"] for b in STARTS["k"]]
    fixed_starts = [{"rms_slope": rms_slope, "n": a, "k": b} for a, b in SCREEN_STARTS]
    rows = []
    for model in _order():
        near = _neighbour_start(model, rows)
        starts = first if near is None else [near] + fixed_starts
        rows.append(_screen(data, screen, band, model, False, fit, fixed, starts))
    if "k" in fit and k0 is None and min(rows, key=lambda r: r.bic).params["k"] < DIELECTRIC_K:
        for r in sorted(rows, key=lambda r: r.bic)[:3]:
            rows.append(_screen(data, screen, band, (r.shadowing, r.diffuse), True, fit, fixed, [r.params]))
    _screen_verdicts(rows)
    return _full_fits(data, rows, fit, rms_slope, n0, k0, strict, progress)


def _screen_verdicts(rows):
    """Adequate on the screen: a misfit in excess of the best screened model's (the floor the data
    allow any model here) within the tolerance.  One band and a few hundred geometries are too few
    for the verdict's own tests; the chosen model's verdict is then made on all the data."""
    best = min(rows, key=lambda r: r.bic).misfit
    for r in rows:
        excess = {q: math.sqrt(max(r.misfit[q] ** 2 - best[q] ** 2, 0.0)) for q in ("M00", "elements")}
        r.adequate = excess["M00"] <= M00_TOLERANCE and excess["elements"] <= ELEMENT_TOLERANCE
        r.note = f"excess misfit over the best: M00 {100 * excess['M00']:.3g} %, elements {excess['elements']:.2g}"


def _full_fits(data, rows, fit, rms_slope, n0, k0, strict, progress):
    """Fit the screen's choice on all the data; if its verdict fails there, the next candidate."""
    from hyde_bsdf.fit.pbsdf_fit import fit_pbsdf

    notes = []
    for _ in range(MAX_FULL_FITS):
        i, why = _choose(rows)
        r = rows[i]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = fit_pbsdf(data, fit=tuple(q for q in fit if not (r.dielectric and q == "k")),
                            rms_slope=rms_slope, n0=n0, k0=0.0 if r.dielectric else k0, shadowing=r.shadowing,
                            diffuse=r.diffuse, progress=progress, start=r.params)
        mid = data.wavelengths.size // 2
        rows[i] = ModelRow(r.shadowing, r.diffuse, r.dielectric, res.params(mid), r.n_params, r.size, r.bic,
                           {"M00": float(np.sqrt(np.mean(res.rms_m00 ** 2))),
                            "elements": float(np.sqrt(np.mean(res.rms_elements ** 2)))},
                           bool(res.verdict.adequate), "full",
                           f"all bands: {len(res.names)} free parameters, misfit over {len(data)} geometries")
        if res.verdict.adequate or not any(x.adequate for x in rows):
            break
        notes.append(f"{r.label} was adequate on the screen but not on every band: {res.verdict.message}")
    sel = ModelSelection(rows + _undefined_rows(), i, why, res, notes=notes)
    _finish(sel, strict)
    return sel

