"""Model selection for lab data (``--model auto`` on a CSV): the simplest model the data need.

Candidates: shadowing {none, smith, vgroove} x diffuse term {none, paper, reciprocal, lambertian}
(the records of :mod:`hyde_bsdf.model.terms`; reciprocal needs shadowing: 11 models); with several wavelengths each Lambertian model also with
one albedo per wavelength; and k = 0 at every wavelength (a dielectric) for the best models
where every fitted k is below :data:`DIELECTRIC_K`.  The first candidate starts from a grid, each
later one from its best already-fitted neighbour (one term changed).

Size of a model: its free parameters plus one for each term it adds (a shadowing function, a
diffuse term: :func:`hyde_bsdf.model.terms`-style ``adds``).  The Lambertian term's albedo is a
free parameter besides, so the paper's diffuse term -- whose size Eq. 17 ties to the roughness --
is the smaller of the two.  Rule:

1. among the *adequate* models (:mod:`hyde_bsdf.fit.adequacy`) the smallest, ties broken by the
   Bayesian information criterion BIC = chi^2 + p ln m;
2. then a larger adequate model replaces it when it fits significantly better: chi^2 lower by more
   than the chi^2 distribution reaches with probability :data:`NESTED_P` for the added size (for a
   model that *contains* the choice -- a free albedo where there was none, an albedo per
   wavelength where one was shared, a free k where it was 0 -- for its added free parameters: the
   difference test).  The absolute chi^2 test of step 1 is blind to what a few thousand values
   show only together: a 2 % Lambertian part that a free albedo finds, or the Smith shadowing of a
   narrow Beckmann lobe (no shadowing: chi^2 higher by ~370 over 4600 values, reduced chi^2 1.06,
   p = 0.003, and rms_slope 4 standard errors off);
3. no adequate model: the lowest BIC, and the verdict says so.

What the data do not decide is said, not hidden: when another adequate model that fits about as
well (its chi^2 not significantly above the chosen one's) gives a parameter more than
:data:`SPREAD_SIGMAS` standard errors away from the chosen one's value, the result warns that the
parameter is not identified by these data (naming the models and their values).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from hyde_bsdf.fit.adequacy import chi2_isf, chi2_sf
from hyde_bsdf.fit.lab_data import LabData
from hyde_bsdf.fit.lab_fit import PARAMETERS, LabModel, ModelFit, fit_model
from hyde_bsdf.model import terms
from hyde_bsdf.model.terms import DIFFUSE_TERMS, SHADOWING_TERMS, allowed

__all__ = ["CANDIDATES", "DIELECTRIC_K", "NESTED_P", "SPREAD_SIGMAS", "ModelRow",
           "Selection", "model_size", "select"]

#: every pair of the terms of model/terms.py their rule allows (none x reciprocal is not: no shadowing,
#: the DHR exceeds 1), simplest first
CANDIDATES = tuple((s.name, d.name) for s in sorted(SHADOWING_TERMS, key=lambda t: t.rank)
                   for d in sorted(DIFFUSE_TERMS, key=lambda t: t.rank) if allowed(s, d))
#: k = 0 variants are tried for models whose fitted k is below this at every wavelength
DIELECTRIC_K = 0.5
#: p-value of the chi^2 difference below which a containing model replaces the choice
NESTED_P = 1e-3
#: standard errors between adequate models' values beyond which a parameter is not identified
SPREAD_SIGMAS = 3.0
#: the first candidate (from the grid); the others follow from their neighbours
FIRST = ("smith", "lambertian")


def model_size(model: LabModel, free_parameters: int) -> int:
    """Free parameters + 1 per term the model adds (a shadowing function, a diffuse term: the
    records' ``adds``, :func:`hyde_bsdf.model.terms.model_size`)."""
    return terms.model_size(model.shadowing, model.diffuse, free_parameters)


@dataclass
class ModelRow:
    """One candidate's fit, for the table."""

    model: LabModel
    fit: ModelFit
    size: int
    bic: float
    chosen: bool = False

    @property
    def adequate(self) -> bool:
        return bool(self.fit.verdict.adequate)


@dataclass
class Selection:
    rows: list
    chosen: int
    reason: str
    notes: list = field(default_factory=list)

    @property
    def choice(self) -> ModelRow:
        return self.rows[self.chosen]


def _neighbour(model: LabModel, rows: list):
    """The best (lowest BIC) fitted model one term away from ``model`` (its values start the fit)."""
    near = [r for r in rows if not r.model.dielectric and
            (r.model.shadowing == model.shadowing) + (r.model.diffuse == model.diffuse) == 1]
    return min(near, key=lambda r: r.bic) if near else None


def _order(lambertian=True):
    """Candidates in an order where each (after the first) has an already-fitted neighbour."""
    first = FIRST if lambertian else (FIRST[0], "none")
    todo = [c for c in CANDIDATES if c != first and (lambertian or not LabModel(*c).lambertian)]
    done = [first]
    while todo:
        nxt = next(c for c in todo if any((c[0] == d[0]) + (c[1] == d[1]) == 1 for d in done))
        todo.remove(nxt)
        done.append(nxt)
    return [LabModel(*c) for c in done]


def _start(model: LabModel, base: ModelFit | None, groups: int) -> dict | None:
    """A neighbour's values as the start of ``model``: an albedo added at 0.01, or dropped; one per
    wavelength from a shared one."""
    if base is None:
        return None
    start = {k: v for k, v in base.values.items() if k[0] != "diffuse_reflectance"}
    shared = base.values.get(("diffuse_reflectance", None), 0.01)
    if model.lambertian and model.albedo == "per_wavelength":
        start.update({("diffuse_reflectance", g): base.values.get(("diffuse_reflectance", g), shared)
                      for g in range(groups)})
    elif model.lambertian:
        start[("diffuse_reflectance", None)] = shared
    return start


def _row(data: LabData, model: LabModel, fit, values, base, tick) -> ModelRow:
    f = fit_model(data, model, fit=fit, values=values, start=_start(model, base, len(data.groups)), tick=tick)
    p = len(f.free)
    return ModelRow(model, f, model_size(model, p), f.chi2 + p * math.log(max(f.residuals.size, 1)))


def select(data: LabData, *, fit=PARAMETERS, values: dict | None = None, albedo=None, lambertian=True,
           tick=None) -> Selection:
    """Fit every candidate to ``data`` and choose (module docstring).  ``fit``, ``values``: as for
    :func:`hyde_bsdf.fit.lab_fit.fit_model` (parameters held fixed in every candidate); ``albedo``:
    "shared" or "per_wavelength" to try only that form of the Lambertian albedo (None: both).
    ``lambertian``: False leaves out the Lambertian candidates (their albedo neither fitted nor given).
    Without sigmas the first candidate's estimate of the noise weighs every candidate."""
    rows = []
    first_form = "per_wavelength" if albedo == "per_wavelength" else "shared"
    for model in _order(lambertian):
        near = _neighbour(model, rows)
        if model.lambertian:
            model = LabModel(model.shadowing, model.diffuse, first_form)
        rows.append(_row(data, model, fit, values, near.fit if near else None, tick))
        data = rows[0].fit.data          # with the estimated noise (no sigmas), or the shared noise along its r
    if len(data.groups) > 1 and lambertian and "diffuse_reflectance" in fit and albedo is None:
        for base in [r for r in rows if r.model.lambertian]:
            rows.append(_row(data, LabModel(base.model.shadowing, base.model.diffuse, "per_wavelength"), fit, values,
                             base.fit, tick))
    ks = lambda r: [v for k, v in r.fit.values.items() if k[0] == "k"]
    if "k" in fit:
        for base in sorted(rows, key=lambda r: r.bic)[:3]:
            if max(ks(base)) < DIELECTRIC_K:
                m = base.model
                rows.append(_row(data, LabModel(m.shadowing, m.diffuse, m.albedo, True), fit, values, base.fit, tick))
    chosen, reason = _choose(rows)
    rows[chosen].chosen = True
    return Selection(rows, chosen, reason, _spread_notes(rows, chosen))


def _contains(big: LabModel, small: LabModel) -> bool:
    """Whether ``small`` is ``big`` with parameters pinned (albedo 0, albedos equal, k = 0)."""
    if big.shadowing != small.shadowing or (big.dielectric and not small.dielectric):
        return False
    same_k = big.dielectric == small.dielectric
    if big.diffuse == small.diffuse:
        return (big.albedo == "per_wavelength" and small.albedo == "shared" and same_k) or \
            (big.albedo == small.albedo and small.dielectric and not big.dielectric)
    return big.lambertian and small.diffuse == "none" and same_k


def _choose(rows):
    """Index of the chosen row and why (module docstring, rules 1-3)."""
    ok = [i for i, r in enumerate(rows) if r.adequate]
    if not ok:
        i = min(range(len(rows)), key=lambda j: rows[j].bic)
        return i, "NO model is adequate; this one has the lowest BIC, and its errors are lower bounds"
    i = min(ok, key=lambda j: (rows[j].size, rows[j].bic))
    why = f"the smallest adequate model (size {rows[i].size}; among equal sizes the lowest BIC)"

    def added(j, i):          # the degrees of freedom of the difference test
        if _contains(rows[j].model, rows[i].model):
            return max(len(rows[j].fit.free) - len(rows[i].fit.free), 1)
        return rows[j].size - rows[i].size if rows[j].size > rows[i].size else 0

    while True:
        better = [j for j in ok if added(j, i) and rows[j].fit.chi2 < rows[i].fit.chi2
                  and chi2_sf(rows[i].fit.chi2 - rows[j].fit.chi2, added(j, i)) < NESTED_P]
        if not better:
            return i, why
        j = min(better, key=lambda b: rows[b].bic)
        how = "contains" if _contains(rows[j].model, rows[i].model) else "is larger than"
        why = (f"{rows[j].model.label} {how} {rows[i].model.label} and fits significantly better "
               f"(chi^2 {rows[i].fit.chi2:.5g} -> {rows[j].fit.chi2:.5g}, p < {NESTED_P:g}); " + why)
        i = j


def _rivals(rows, chosen) -> list:
    """The adequate models the data do not rule out against the choice: their chi^2 exceeds the
    chosen one's by less than the difference test's limit (p = NESTED_P, the sizes' difference as
    degrees of freedom, at least 1) -- a model the choice beat in rule 2 is no rival."""
    c = rows[chosen]
    return [r for r in rows if r.adequate and not r.chosen and
            r.fit.chi2 - c.fit.chi2 < chi2_isf(NESTED_P, max(abs(r.size - c.size), 1))]


def _spread_notes(rows, chosen) -> list:
    """Parameters on which the rival adequate models (:func:`_rivals`) disagree beyond SPREAD_SIGMAS
    of the chosen one's errors."""
    c = rows[chosen].fit
    rivals = _rivals(rows, chosen)
    notes = []
    for key in c.free:
        e = c.stderr[key]
        if not math.isfinite(e) or e <= 0:
            continue
        others = [(r.model.label, r.fit.values[key]) for r in rivals if key in
                  r.fit.values and abs(r.fit.values[key] - c.values[key]) > SPREAD_SIGMAS * e]
        if others:
            far = max(others, key=lambda o: abs(o[1] - c.values[key]))
            notes.append(f"{c.name(key)} is not identified by these data: the adequate model {far[0]} gives "
                         f"{far[1]:.4g}, {abs(far[1] - c.values[key]) / e:.1f} standard errors from the chosen "
                         f"{c.values[key]:.4g} +- {e:.2g}" + (f" ({len(others)} adequate models differ so)"
                                                              if len(others) > 1 else ""))
    return notes
