"""Fitting lab Mueller data: :func:`fit_lab`, what ``hyde-bsdf fit DATA.csv`` runs.

Data: a CSV as :mod:`hyde_bsdf.io.measurements` reads it -- the normalized elements M_jk/M_00,
optionally the BRDF M00 in 1/sr and a wavelength column -- or its
:class:`~hyde_bsdf.io.measurements.Measurements`.  Fitted by default: everything the data
determine (rms_slope, n and k per wavelength, the Lambertian albedo ``diffuse_reflectance``);
the model (shadowing x diffuse term) is chosen (:mod:`hyde_bsdf.fit.lab_selection`) unless given.
Several wavelengths are one joint fit: one roughness, an index per wavelength, the albedo shared
or per wavelength as the data decide (:mod:`hyde_bsdf.fit.lab_fit`).

What the data cannot say is said (``LabFitResult.warnings``, the JSON's ``verdict.warnings``):
without M00 the roughness is seen only through the size of the diffuse part relative to the
specular lobe (the note gives its relative error and its correlation with the albedo), or not at
all without a diffuse term; adequate models that disagree on a parameter mark it as not
identified; a misfit caused by a parameter held fixed names that parameter, never the sigmas.

:meth:`LabFitResult.to_dict` is the machine-readable result (``--json FILE``)::

    {"model": {"shadowing": ..., "diffuse": ...},
     "parameters": [{"name": "rms_slope" | "n" | "k" | "diffuse_reflectance",
                     "wavelength_nm": null | number, "value": ..., "stderr": ... | null}, ...],
     "covariance": {"names": [...], "matrix": [[...]]},
     "verdict": {"adequate": bool, "chi2_reduced": ..., "p_value": ..., "warnings": [...]},
     "models": [...the auto table: one row per candidate...]}

``stderr`` is null for a parameter held fixed (by the user, or because the data do not determine
it); covariance names are ``rms_slope``, ``n@632.8nm``, ... (a parameter shared by the wavelengths
without the suffix; without a wavelength column none has one).  Non-finite numbers are null.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError, shorten
from hyde_bsdf.fit.adequacy import (ERRORS_NOTE, InadequateModelError, InadequateModelWarning, json_number,
                                    without_advice)
from hyde_bsdf.fit.lab_data import lab_data
from hyde_bsdf.fit.lab_fit import BOUNDS, PARAMETERS, LabModel, ModelFit, blame_fixed, check_enough, fit_model
from hyde_bsdf.fit.lab_selection import Selection, model_size, select
from hyde_bsdf.fit.spectral import spectrum_element, wavelength_note
from hyde_bsdf.fit.mueller_fit import FitDataWarning, IllPosedFitError, IllPosedFitWarning, impossible_values
from hyde_bsdf.io.measurements import Measurements, read_measurements
from hyde_bsdf.model.evaluator import pbrdf
from hyde_bsdf.model.terms import DIFFUSE, SHADOWING, check_pair, diffuse_term
from hyde_bsdf.progress import PROGRESS_SECONDS, EvaluationCounter, as_callback, check_progress

__all__ = ["LabFitResult", "fit_lab", "check_lab_options", "material_at"]

#: the diffuse terms a CSV fit takes (every record of model/terms.py)
DIFFUSE_CHOICES = DIFFUSE
ALBEDO_CHOICES = ("shared", "per_wavelength")
#: with ``progress=None`` only a problem of more geometries reports its progress
LARGE_GEOMETRIES = 4000


def _names(fit) -> tuple:
    if fit is None:
        return PARAMETERS
    if isinstance(fit, str):
        fit = tuple(p.strip() for p in fit.split(",") if p.strip())
    fit = tuple(fit)
    if not fit or any(p not in PARAMETERS for p in fit) or len(set(fit)) != len(fit):
        raise UsageError(f"fit must be a non-empty subset of {','.join(PARAMETERS)} without repeats, got "
                         f"{shorten(','.join(map(str, fit)))}")
    return tuple(p for p in PARAMETERS if p in fit)


def _value(name, v, per_wavelength=False):
    """A start or fixed value: a real number in the parameter's range (a sequence per wavelength for n, k)."""
    if v is None:
        return None
    if per_wavelength and isinstance(v, (list, tuple, np.ndarray)):
        return [_value(name, x) for x in v]
    if isinstance(v, (bool, str, bytes, complex)):
        raise UsageError(f"{name} must be a real number, got {shorten(v)}")
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise UsageError(f"{name} must be a real number, got {shorten(v)}") from None
    lo, hi = BOUNDS[{"n0": "n", "k0": "k"}.get(name, name)]
    if not (math.isfinite(x) and lo <= x <= hi):
        raise UsageError(f"{name} must be in [{lo:g}, {hi:g}], got {shorten(v)}")
    return x


def check_lab_options(fit=None, shadowing=None, diffuse=None, albedo=None, rms_slope=None, n0=None, k0=None,
                      diffuse_reflectance=None) -> dict:
    """:func:`fit_lab`'s options checked without data (the command line checks them before reading).
    Returns them normalized; UsageError naming the option otherwise."""
    names = _names(fit)
    if shadowing is not None or diffuse is not None:
        check_pair(shadowing or SHADOWING[0], diffuse or DIFFUSE[0], booleans=False)
    if albedo is not None and albedo not in ALBEDO_CHOICES:
        raise UsageError(f"albedo must be one of {ALBEDO_CHOICES}, got {shorten(albedo)}")
    given = {"rms_slope": _value("rms_slope", rms_slope), "n": _value("n0", n0, True), "k": _value("k0", k0, True),
             "diffuse_reflectance": _value("diffuse_reflectance", diffuse_reflectance)}
    for q in PARAMETERS:
        # a Lambertian albedo neither fitted nor given: no Lambertian candidate (an error if one is asked for)
        if q not in names and given[q] is None and not (q == "diffuse_reflectance" and
                                                         q not in diffuse_term(diffuse or DIFFUSE[0]).parameters):
            flag = {"n": "n0", "k": "k0"}.get(q, q)
            raise UsageError(f"{flag} must be given when {q} is not fitted (it is then held at that value)")
    return {"fit": names, "shadowing": shadowing, "diffuse": diffuse, "albedo": albedo, "given": given}


def _values(given: dict, groups: int) -> dict:
    """The user's values as parameter keys (a scalar n0/k0 for every wavelength)."""
    out = {}
    if given["rms_slope"] is not None:
        out[("rms_slope", None)] = given["rms_slope"]
    for q in ("n", "k"):
        v = given[q]
        if v is None:
            continue
        if isinstance(v, list):
            if len(v) != groups:
                raise UsageError(f"{q}0 has {len(v)} values for {groups} wavelength(s): give one, or one per wavelength")
            out.update({(q, g): x for g, x in enumerate(v)})
        else:
            out.update({(q, g): v for g in range(groups)})
    if given["diffuse_reflectance"] is not None:
        out[("diffuse_reflectance", None)] = given["diffuse_reflectance"]
        out.update({("diffuse_reflectance", g): given["diffuse_reflectance"] for g in range(groups)})
    return out


@dataclass
class LabFitResult:
    """The result of :func:`fit_lab`: the chosen model's fit, the table of candidates, the warnings."""

    fit: ModelFit
    selection: Selection | None = None
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)        # said for information (summary, JSON), not warned
    source: str = "<memory>"
    blamed: ModelFit | None = None       # the same model with every parameter free, when fixing caused a misfit

    @property
    def model(self) -> LabModel:
        return self.fit.model

    @property
    def verdict(self):
        return self.fit.verdict

    @property
    def wavelengths(self) -> list:
        return self.fit.data.wavelengths

    @property
    def success(self) -> bool:
        return self.fit.success

    @property
    def ill_posed_notes(self) -> list:
        """What makes the fit ill-posed (strong correlations, poorly determined or bounded values)."""
        return list(self.fit.warnings)

    def params(self, wavelength=None) -> dict:
        """rms_slope, n, k (and diffuse_reflectance) at a measured wavelength (nm; None: the only one),
        the keywords of :func:`hyde_bsdf.pbrdf` (with ``shadowing`` and ``diffuse``)."""
        wls = self.wavelengths
        if wavelength is None and len(wls) == 1:
            g = 0
        elif wavelength is not None and any(w is not None and abs(w - wavelength) < 1e-9 for w in wls):
            g = next(i for i, w in enumerate(wls) if w is not None and abs(w - wavelength) < 1e-9)
        else:
            raise UsageError(f"wavelength must be one of the measured {', '.join(f'{w:g}' for w in wls if w)} nm, "
                             f"got {shorten(wavelength)}")
        return {**self.fit.params(g), "shadowing": self.model.shadowing, "diffuse": self.model.diffuse}

    def mueller(self, theta_i, theta_r, phi, wavelength=None) -> np.ndarray:
        """The fitted model's F (1/sr, paper bases, shape (..., 4, 4)) at a measured wavelength."""
        return pbrdf(theta_i, theta_r, phi, **self.params(wavelength))

    def parameters(self) -> list:
        """Every parameter as {"name", "wavelength_nm", "value", "stderr"} (stderr None when held fixed)."""
        out = []
        for key, v in self.fit.values.items():
            q, g = key
            wl = None if g is None else self.fit.data.groups[g].wavelength
            e = self.fit.stderr.get(key)
            out.append({"name": q, "wavelength_nm": wl, "value": json_number(v),
                        "stderr": None if e is None else json_number(e)})
        order = {q: i for i, q in enumerate(PARAMETERS)}
        return sorted(out, key=lambda p: (order[p["name"]], -1 if p["wavelength_nm"] is None else p["wavelength_nm"]))

    def to_dict(self) -> dict:
        """The machine-readable result (module docstring; what ``--json FILE`` writes)."""
        f = self.fit
        cov = [[json_number(x) for x in row] for row in np.asarray(f.covariance, float)]
        return {"model": {"shadowing": self.model.shadowing, "diffuse": self.model.diffuse},
                "parameters": self.parameters(),
                "covariance": {"names": [f.name(k) for k in f.free], "matrix": cov},
                "verdict": {"adequate": bool(f.verdict.adequate), "chi2_reduced": json_number(f.reduced_chi2),
                            "p_value": json_number(f.p_value) if f.data.sigma_given else None,
                            "warnings": list(self.warnings) + list(self.notes)},
                "models": [_row_dict(r) for r in self.selection.rows] if self.selection else [_fit_dict(f, True)]}

    def summary(self) -> str:
        """A human-readable report: the table of models, the parameters, the verdict, the warnings."""
        f, out = self.fit, []
        if self.selection is not None:
            out += [f"model selection ({len(self.selection.rows)} models; size = free parameters + terms; "
                    "BIC = chi^2 + p ln m):", _table(self.selection), f"  chosen: {self.model.label} -- "
                    f"{self.selection.reason}"]
        d = f.data
        out.append(f"pBRDF fit (shadowing={self.model.shadowing!r}, diffuse={self.model.diffuse!r}"
                   + (", k = 0" if self.model.dielectric else "") + f"): {d.y.size} values ({', '.join(d.columns)}) "
                   f"at {d.geometries} geometries, {len(d.groups)} wavelength(s), {len(f.free)} fitted parameters")
        out.append(f"  optimizer converged: {f.success} ({f.message}; {f.nfev} evaluations)")
        params = self.parameters()
        labels = [p["name"] + ("" if p["wavelength_nm"] is None else f" @ {p['wavelength_nm']:g} nm") for p in params]
        width = max(9, *map(len, labels))
        for p, label in zip(params, labels):
            v, e = p["value"], p["stderr"]
            err = "(fixed)" if e is None else (f"+- {e:.3g}" + (f" ({100 * e / abs(v):.2g} %)" if v else ""))
            out.append(f"  {label:{width}s} = {v:.6g} {err}")
        out.append("  index: the paper's eta = n - jk; Mitsuba/plugin eta = n, k = k (n + ik), the same numbers")
        noise = "" if d.sigma_given else "  [no sigmas: the noise was estimated from the residuals]"
        out.append(f"  chi^2 = {f.chi2:.5g}, dof = {f.dof}, reduced chi^2 = {f.reduced_chi2:.4g}" +
                   (f", p = {f.p_value:.3g}" if d.sigma_given else "") + noise)
        out.append(f"  model {f.verdict.line()}")
        out.append("  standard errors: " + ERRORS_NOTE[f.verdict.errors])
        out += [f"  WARNING: {w}" for w in self.warnings] + [f"  NOTE: {w}" for w in self.notes]
        return "\n".join(out)

    # ---- the material for a scene
    def plugin_xml(self, indent: str = "") -> str:
        """The ``hyde`` ``<bsdf>``: rms_slope, the index as a spectrum over the measured wavelengths
        (Mitsuba's ``wavelength:value`` pairs: 0 outside their range, where the plugin then reflects
        nothing and warns), the albedo; with one wavelength the index as a number and a comment that
        it holds there only."""
        f, wls = self.fit, self.wavelengths
        pr = [f.params(g) for g in range(len(wls))]
        lines = [f'{indent}<bsdf type="hyde">', f'{indent}    <float name="rms_slope" value="{pr[0]["rms_slope"]:.6g}"/>']
        lines.append(f"{indent}    <!-- {wavelength_note(wls)} -->")
        lines.append(f"{indent}    <!-- Mitsuba n + ik; the paper writes eta = n - jk with the same numbers -->")
        for q, name in (("n", "eta"), ("k", "k")):
            lines.append(f"{indent}    {spectrum_element(name, wls, [p[q] for p in pr])}")
        lines += [f'{indent}    <string name="shadowing" value="{self.model.shadowing}"/>',
                  f'{indent}    <string name="diffuse" value="{self.model.diffuse}"/>']
        if self.model.lambertian:
            lines.append(f"{indent}    {spectrum_element('diffuse_reflectance', wls, [p['diffuse_reflectance'] for p in pr])}")
        return "\n".join(lines + [f"{indent}</bsdf>"])


def _fit_dict(f: ModelFit, chosen: bool) -> dict:
    m = f.model
    return {"shadowing": m.shadowing, "diffuse": m.diffuse, "albedo": m.albedo if m.lambertian else None,
            "dielectric": m.dielectric, "free_parameters": len(f.free), "size": model_size(m, len(f.free)),
            "chi2": json_number(f.chi2), "dof": f.dof, "chi2_reduced": json_number(f.reduced_chi2),
            "p_value": json_number(f.p_value) if f.data.sigma_given else None, "adequate": bool(f.verdict.adequate),
            "chosen": chosen, "values": {f.name(k): json_number(v) for k, v in f.values.items()}}


def _row_dict(row) -> dict:
    return {**_fit_dict(row.fit, row.chosen), "bic": json_number(row.bic)}


def _table(sel: Selection) -> str:
    head = f"  {'model':32s} {'params':>6s} {'size':>4s} {'BIC':>12s} {'chi2_red':>9s} {'rms_slope':>9s}  verdict"
    out = [head]
    for r in sel.rows:
        f = r.fit
        tag = ("adequate" if r.adequate else "inadequate") + (" <- chosen" if r.chosen else "")
        out.append(f"  {r.model.label:32s} {len(f.free):6d} {r.size:4d} {r.bic:12.6g} {f.reduced_chi2:9.4g} "
                   f"{f.values[('rms_slope', None)]:9.4g}  {tag}")
    return "\n".join(out)


def _roughness_note(f: ModelFit) -> tuple:
    """Without M00: how (and how weakly) the roughness is determined -- (text or None, whether it is
    a warning: weakly, above 10 %, or not at all: a Lambertian albedo not distinguished from 0)."""
    key = ("rms_slope", None)
    if f.data.has_m00 or key not in f.free:
        return None, False
    v, e = f.values[key], f.stderr[key]
    albedos = [(f.name(k), f.values[k], f.stderr[k]) for k in f.free if k[0] == "diffuse_reflectance"]
    if albedos and all(not (a > 3 * ea) for _, a, ea in albedos):
        shown = ", ".join(f"{name} = {a:.3g} +- {ea:.2g}" for name, a, ea in albedos)
        return (f"rms_slope is not identified: without M00 it is seen only through the diffuse part, and the "
                f"Lambertian albedo ({shown}) is not distinguished from 0 (within 3 standard errors): its value "
                f"{v:.4g} +- {e:.2g} describes no measured effect -- measure M00 (1/sr) to see the lobe's width"), True
    rel = e / v if v > 0 else math.inf
    how = ("the size of the diffuse part relative to the specular lobe" if not f.model.lambertian else
           "the depolarized part's change over the geometries (the lobe's shape: the albedo is free")
    if f.model.lambertian and ("diffuse_reflectance", None) in f.free:
        i, j = f.free.index(key), f.free.index(("diffuse_reflectance", None))
        how += f", correlation with it {f.correlation[i, j]:+.2f})"
    elif f.model.lambertian:
        how += ")"
    return (f"without M00 the roughness is determined only through the diffuse term ({f.model.diffuse}): by {how}; "
            f"rms_slope = {v:.4g} +- {e:.2g} ({100 * rel:.2g} %{', weakly' if rel > 0.1 else ''}), and only as far as "
            "the diffuse term is right -- measure M00 (1/sr) to see the lobe's width itself"), rel > 0.1


def _repeats_notes(data) -> list:
    out = []
    for g in data.groups:
        if g.uninformative:
            out.append(f"{g.label}: {g.uninformative} of {g.rows_in} rows left out -- their normalized values are "
                       "ratios over an M00 not known to be above 0 within 3 sigma (the sigmas imply its relative "
                       "error is above 1/3): a ratio of noises, which looks depolarized; measure M00 (1/sr) to use them")
        if g.repeats:
            r = g.repeats
            out.append(f"{g.label}: {r['repeated_rows']} of {r['rows']} rows repeat another row's geometry; they were "
                       f"merged into {r['geometries']} geometries (inverse-variance means)" +
                       (f", {r['copy_geometries']} of them identical copies, which count once" if r['copy_geometries']
                        else ""))
    return out


def impossible_notes(meas: Measurements) -> list:
    """Normalized values no Mueller matrix has beyond what their noise reaches by chance
    (:func:`~hyde_bsdf.fit.mueller_fit.impossible_values`, the reader's file-size limit; the
    reader refuses single elements beyond it, so these are mostly degrees of polarization above 1
    or data built in Python)."""
    if meas.sigma is None or not meas.values:
        return []
    return [f"impossible data: {what} beyond {limit:.2g} sigma (worst {v:.4g} +- {e:.2g} at theta_i="
            f"{math.degrees(meas.theta_i[i]):.4g}, theta_r={math.degrees(meas.theta_r[i]):.4g}, "
            f"phi={math.degrees(meas.phi[i]):.4g} deg"
            + ("" if meas.wavelength_nm is None else f", {meas.wavelength_nm[i]:g} nm") + "): no Mueller matrix "
            "has it -- a calibration error, or sigmas too small; the fit cannot describe these values"
            for what, i, v, e, limit in impossible_values(meas.values, meas.uncertainty())]


def _collect_warnings(f: ModelFit, sel: Selection | None, meas: Measurements) -> tuple:
    """(warnings, notes): what limits the result, and what is said for information (the roughness
    note without M00 -- a warning when the roughness is weakly determined, above 10 %, or not at all)."""
    out = []
    if not f.verdict.adequate:
        out.append(("NO candidate model is adequate; the best: " if sel is not None else "") + f.verdict.message)
    out += list(f.warnings) + list(f.notes) + (sel.notes if sel is not None else [])
    (note, warn), notes = _roughness_note(f), []
    if note and warn:
        out.append(note)
    elif note:
        notes.append(note)
    return out + impossible_notes(meas) + _repeats_notes(f.data), notes


def fit_lab(data, *, fit=None, shadowing=None, diffuse=None, albedo=None, rms_slope=None, n0=None, k0=None,
            diffuse_reflectance=None, strict=False, progress=None) -> LabFitResult:
    """Fit lab Mueller data (module docstring); returns a :class:`LabFitResult`.

    ``data``: :class:`~hyde_bsdf.io.measurements.Measurements` or the path of a CSV.
    ``fit``: the parameters to fit (``"rms_slope,n,k,diffuse_reflectance"`` or a tuple; None: all the
    data determine); the others are held at ``rms_slope``, ``n0``, ``k0`` (one value, or one per
    wavelength in ascending order), ``diffuse_reflectance`` -- which are start values for the fitted
    ones (None: a grid).  ``shadowing``, ``diffuse`` (``"paper"``, ``"reciprocal"``, ``"none"``,
    ``"lambertian"``): one model (a name left None takes vgroove / paper); both None: the model is
    chosen.  ``albedo``: ``"shared"`` or ``"per_wavelength"`` (the Lambertian albedo; None: chosen
    when the model is, shared otherwise).  ``strict``: raise
    :class:`~hyde_bsdf.fit.adequacy.InadequateModelError` / :class:`~hyde_bsdf.fit.IllPosedFitError`
    instead of warning.  ``progress``: a callback, True (stderr lines), False (none) or None (lines for
    more than :data:`LARGE_GEOMETRIES` geometries).
    """
    opts = check_lab_options(fit, shadowing, diffuse, albedo, rms_slope, n0, k0, diffuse_reflectance)
    check_progress(progress)
    meas = data if isinstance(data, Measurements) else read_measurements(Path(data))
    d = lab_data(meas)
    values = _values(opts["given"], len(d.groups))
    auto = d.geometries > LARGE_GEOMETRIES if progress is None else progress    # None: only a large problem reports
    counter = EvaluationCounter(as_callback(auto), PROGRESS_SECONDS)
    lambertian = "diffuse_reflectance" in opts["fit"] or diffuse_reflectance is not None
    wanted = [(q, g) for q in ("n", "k") if q in opts["fit"] for g in range(len(d.groups))]
    wanted += [("rms_slope", None)] * ("rms_slope" in opts["fit"])
    wanted += [("diffuse_reflectance", None)] * ("diffuse_reflectance" in opts["fit"] and lambertian)
    check_enough(d, wanted)
    sel = None
    if shadowing is None and diffuse is None:
        counter.stage = "fitting every candidate model"
        sel = select(d, fit=opts["fit"], values=values, albedo=albedo, lambertian=lambertian, tick=counter.tick)
        chosen = sel.choice.fit
        without_advice(chosen.verdict)           # every model was tried: no "try --model auto"
    else:
        model = LabModel(shadowing or SHADOWING[0], diffuse or DIFFUSE[0], albedo or "shared")
        counter.stage = f"fitting {model.label}"
        chosen = fit_model(d, model, fit=opts["fit"], values=values, tick=counter.tick)
    blamed = blame_fixed(chosen.data, chosen, counter.tick)
    counter.done()
    warned, notes = _collect_warnings(chosen, sel, meas)
    result = LabFitResult(chosen, sel, warned, notes, meas.source, blamed)
    _raise_or_warn(result, strict)
    return result


def _raise_or_warn(result: LabFitResult, strict: bool):
    f = result.fit
    if not f.verdict.adequate:
        if strict:
            raise InadequateModelError(result.warnings[0])
        warnings.warn(result.warnings[0], InadequateModelWarning, stacklevel=3)
    if f.warnings:
        text = "ill-posed fit: " + "; ".join(f.warnings)
        if strict:
            raise IllPosedFitError(text)
        warnings.warn(text, IllPosedFitWarning, stacklevel=3)
    for text in result.warnings[int(not f.verdict.adequate):]:
        if text not in f.warnings:
            warnings.warn(text, FitDataWarning, stacklevel=3)


def material_at(result: dict, wavelengths, extrapolate: bool = False) -> dict:
    """A fit's material (its JSON dict, :meth:`LabFitResult.to_dict`) at ``wavelengths`` (nm): rms_slope,
    shadowing, diffuse, and n, k and the albedo per wavelength, interpolated linearly between the
    measured wavelengths.  A wavelength outside them -- every other one, for a fit at one
    wavelength -- is refused (UsageError naming it and the measured ones) unless ``extrapolate``:
    then the nearest measured values are held there, and ``"extrapolated"`` lists those wavelengths."""
    try:
        params = {(p["name"], p["wavelength_nm"]): float(p["value"]) for p in result["parameters"]}
        model = result["model"]
        shadowing, diffuse = str(model["shadowing"]), str(model["diffuse"])
    except (KeyError, TypeError, ValueError) as exc:
        raise UsageError(f"not a fit result (the JSON the fit command writes): {shorten(exc)}") from None
    measured = sorted({wl for (name, wl) in params if name == "n" and wl is not None})
    wanted = [float(w) for w in wavelengths]
    outside = [w for w in wanted if not measured or w < measured[0] - 1e-9 or w > measured[-1] + 1e-9]
    if outside and not extrapolate:
        at = f"measured at {', '.join(f'{w:g}' for w in measured)} nm" if measured else "measured at no stated wavelength"
        raise UsageError(f"the fit was {at}; the export needs {', '.join(f'{w:g}' for w in outside)} nm, outside "
                         "them: its index there is unknown -- measure there, or give `extrapolate` to hold the "
                         "nearest measured values (a guess)")

    def curve(name):
        if (name, None) in params:               # shared by the wavelengths (or no wavelength column)
            return [params[(name, None)]] * len(wanted)
        pts = sorted((wl, v) for (q, wl), v in params.items() if q == name)
        if not pts:
            return None
        return list(np.interp(wanted, [w for w, _ in pts], [v for _, v in pts]))

    rms = params.get(("rms_slope", None))
    if rms is None:
        raise UsageError("not a fit result (the JSON the fit command writes): no rms_slope")
    return {"rms_slope": rms, "shadowing": shadowing, "diffuse": diffuse, "n": curve("n"), "k": curve("k"),
            "diffuse_reflectance": curve("diffuse_reflectance"), "measured_nm": measured, "extrapolated": outside}
