"""Model adequacy and model selection (``--model auto``) on data the package did not fit to itself.

1. Synthetic Mueller CSV data with sigmas (theta_i = 20, 45, 70 deg, theta_r = 10..80 deg, phi = 0,
   90, 180 deg; M01, M10, M11, M22, M23, M33 over M00, means of 256 samples of noise 0.03) from each
   of the nine shadowing x diffuse combinations (none x reciprocal is undefined: eight), eta =
   1.2 - j7.0, rms_slope 0.25: :func:`select_model` -- the model chosen, its parameters, reduced
   chi^2, the verdict; the pull std of its standard errors over repeated noise (fixed seeds).
2. Synthetic ``.pbsdf`` tables (``hyde-bsdf export``, Cu, rms_slope 0.2) from each combination:
   :func:`select_model_pbsdf`; the pull std over noise added to the table (1 % in M00, 0.005 in the
   normalized elements), refitting the chosen model.
3. Tables made here from Mitsuba's own C++ BSDFs (the ``llvm_ad_spectral_polarized`` eval in the
   table's frames): roughconductor (Beckmann) for Au and Cu at alpha 0.1 and 0.3, pplastic
   (Beckmann alpha 0.2, eta 1.49) without and with a diffuse base (0.5).  The *default* selection
   must recover alpha within 3 % and n, k within 5 % in every band on the conductors; pplastic with
   a diffuse base is outside the model, and must be warned.  Mitsuba's rational Smith
   approximation against the exact form is a known small mismatch: the pulls of alpha with the
   classic and the reported (robust) errors, noiseless and over repeated small noise.
4. Silent misfits: the issue's wrong fits (the default vgroove/paper on a Smith conductor, a
   dielectric with a diffuse base fitted without one, a material outside the model) and every
   chosen fit; a fit whose rms misfit exceeds the tolerance without an InadequateModelWarning is
   silent.  Target 0.

Targets: the generating model or an equally adequate smaller one is chosen every time; conductors:
alpha within 3 %, n, k within 5 %; 0 silent misfits; pull std 0.8-1.25 wherever errors are claimed
(the verdict's errors are not "lower bounds").

Writes fit_model_selection.png and .csv (one row per case), fit_model_selection_mitsuba.csv,
fit_model_selection_pulls.csv.

    python hyde_bsdf/validation/fit_model_selection.py [-o OUTDIR] [--quick]
"""
from __future__ import annotations

import math
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from hyde_bsdf.fit import fit_mueller, synthetic_measurements
from hyde_bsdf.fit.adequacy import ELEMENT_TOLERANCE, M00_TOLERANCE, InadequateModelWarning
from hyde_bsdf.fit.model_selection import CANDIDATES, select_model, select_model_pbsdf
from hyde_bsdf.model.terms import allowed, model_size
from hyde_bsdf.fit.pbsdf_bands import choose_bands, index_spectrum
from hyde_bsdf.fit.pbsdf_export import _edge_directions, band_index, edge_deg, export_pbsdf, grids
from hyde_bsdf.fit.pbsdf_samples import paper_angles, paper_to_table, pbsdf_samples
from hyde_bsdf.io.pbsdf_file import KAIST_WAVELENGTHS, rusinkiewicz_to_directions, write_pbsdf
from hyde_bsdf.fit.pbsdf_fit import fit_pbsdf

from hyde_bsdf.validation._common import cli, save_figure, write_csv  # noqa: E402

MODELS = [c for c in CANDIDATES if allowed(*c)]
CSV_TRUTH = {"rms_slope": 0.25, "n": 1.2, "k": 7.0}
CSV_ELEMENTS = ("M01", "M10", "M11", "M22", "M23", "M33")
TABLE_RMS = 0.2
PULL_RANGE = (0.8, 1.25)
CONDUCTORS = [("Au", 0.1), ("Au", 0.3), ("Cu", 0.1), ("Cu", 0.3)]
PPLASTIC_ETA = 1.49
#: geometries of the noisy refits (pulls)
PULL_ROWS = 600
#: geometries of the quick run's fits that grade a misfit (pplastic outside the model, the silent-misfit cases):
#: what they test is a systematic misfit -- the rms residual of a wrong model against the adequacy tolerance,
#: the same whatever the geometries drawn -- not a statistical error that shrinks with more points; 200 random
#: cells of the 9 x 16 x 16 table still sample the lobe and the wing of every band (the full run: 1500)
QUICK_MISFIT_POINTS = 200


def csv_geometry():
    ti, tr, ph = np.meshgrid(np.radians([20.0, 45.0, 70.0]), np.radians(np.arange(10.0, 81.0, 10.0)),
                             np.radians([0.0, 90.0, 180.0]), indexing="ij")
    return ti.ravel(), tr.ravel(), ph.ravel()


def correct(chosen, generating, adequate):
    """The generating model, or an adequate one no larger."""
    return chosen == generating or (adequate and model_size(*chosen, 0) <= model_size(*generating, 0))


def _quiet(fn, *args, **kwargs):
    """Call ``fn``; returns (result, InadequateModelWarning messages)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args, **kwargs)
    return out, [str(w.message) for w in caught if issubclass(w.category, InadequateModelWarning)]


def pull_std(pulls):
    p = np.asarray([x for x in pulls if math.isfinite(x)])
    return float(p.std(ddof=1)) if p.size > 2 else float("nan")


# ---------------------------------------------------------------------------------------------
# 1. CSV with sigmas

def csv_case(model, reps, seed):
    ti, tr, ph = csv_geometry()
    make = lambda s: synthetic_measurements(ti, tr, ph, CSV_ELEMENTS, **CSV_TRUTH, noise=0.03, n_samples=256,
                                            rng=s, shadowing=model[0], diffuse=model[1])
    m = make(seed)
    sel, _ = _quiet(select_model, m.theta_i, m.theta_r, m.phi, m.values, sigma=m.uncertainty(),
                    fit=("n", "k", "rms_slope"))
    c, res = sel.choice, sel.result
    # without a diffuse term rms_slope cancels from every normalized element: only n, k are claimed
    names = tuple(q for q in res.fitted if not (c.diffuse == "none" and q == "rms_slope"))
    start = {**res.params, "rms_slope": res.params["rms_slope"] if "rms_slope" in names else CSV_TRUTH["rms_slope"]}
    pulls = []
    for r in range(reps):
        mr = make(seed + 1000 + r)
        f, _ = _quiet(fit_mueller, mr.theta_i, mr.theta_r, mr.phi, mr.values, sigma=mr.uncertainty(),
                      fit=names, rms_slope=start["rms_slope"], n0=start["n"], k0=start["k"],
                      shadowing=c.shadowing, diffuse=c.diffuse)
        if f.verdict.errors != "lower bounds":
            pulls += [(f.params[q] - CSV_TRUTH[q]) / f.stderr[q] for q in f.fitted
                      if not _ill(f, q) and math.isfinite(f.stderr[q])]
    return {"kind": "csv", "case": f"{model[0]}/{model[1]}", "generating": f"{model[0]}/{model[1]}",
            "chosen": c.label, "correct": correct((c.shadowing, c.diffuse), model, res.verdict.adequate),
            "adequate": res.verdict.adequate, "misfit": f"chi2_red {res.reduced_chi2:.3g}",
            "rms_slope": res.params["rms_slope"], "n": res.params["n"], "k": res.params["k"],
            "errors": res.verdict.errors, "pull_std": pull_std(pulls), "pulls": len(pulls)}


def _ill(fit, q):
    """A parameter whose error is not claimed: the fit says it is poorly determined or on a bound."""
    return any(w.startswith(q + " ") for w in fit.warnings)


# ---------------------------------------------------------------------------------------------
# 2. synthetic tables

def noisy(data, rng, m00=0.01, elements=0.005):
    """A copy of the samples with independent noise in the fit's terms: relative ``m00`` on M00,
    absolute ``elements`` on each M_jk/M00."""
    F00 = data.F[..., 0, 0]
    N = data.F / F00[..., None, None] + elements * rng.standard_normal(data.F.shape)
    N[..., 0, 0] = 1.0
    F = N * (F00 * (1 + m00 * rng.standard_normal(F00.shape)))[..., None, None]
    return type(data)(**{**data.__dict__, "F": F})


def subset(data, count, seed=0):
    """At most ``count`` of the samples' geometries (fixed seed)."""
    if len(data) <= count:
        return data
    keep = np.sort(np.random.default_rng(seed).choice(len(data), count, replace=False))
    return type(data)(**{**data.__dict__, "theta_i": data.theta_i[keep], "theta_r": data.theta_r[keep],
                         "phi": data.phi[keep], "F": data.F[:, keep], "cells": data.cells[keep]})


def table_pulls(data, sel, truth, reps, seed, m00=0.01, elements=0.005):
    """Pulls of rms_slope, n, k (every band) refitting the chosen model to noisy copies of
    :data:`PULL_ROWS` of the geometries."""
    c, res = sel.choice, sel.result
    pulls = {"rms_slope": [], "n": [], "k": []}
    rng = np.random.default_rng(seed)
    data = subset(data, PULL_ROWS)
    for _ in range(reps):
        f, _ = _quiet(fit_pbsdf, noisy(data, rng, m00, elements), fit=("n", "rms_slope") if c.dielectric else
                      ("n", "k", "rms_slope"), k0=0.0 if c.dielectric else None, shadowing=c.shadowing,
                      diffuse=c.diffuse, progress=False, start=res.params(data.wavelengths.size // 2))
        if f.verdict.errors == "lower bounds":
            continue
        pulls["rms_slope"].append((f.rms_slope - truth["rms_slope"]) / f.stderr["rms_slope"])
        for q in ("n", "k"):
            if not (c.dielectric and q == "k"):
                pulls[q] += list((getattr(f, q) - truth[q]) / f.stderr[q])
    return pulls


def table_case(model, folder, quick, reps, seed):
    path = Path(folder) / f"{model[0]}_{model[1]}.pbsdf"
    # the KAIST bands with Cu sampled at them, as a measured table has them
    kaist = choose_bands(index_spectrum("Cu"), KAIST_WAVELENGTHS, "sampled")
    report = export_pbsdf(path, rms_slope=TABLE_RMS, material="Cu", shadowing=model[0], diffuse=model[1],
                          resolution=(9, 16, 16) if quick else (13, 24, 24), error_samples=0, alpha_sample=0.3,
                          bands=kaist)
    data = pbsdf_samples(path, max_points=400 if quick else 1500)
    sel, _ = _quiet(select_model_pbsdf, data, progress=False)
    c, res = sel.choice, sel.result
    n, k = np.array(report.params["n"]), np.array(report.params["k"])      # the index the table holds per band
    pulls = table_pulls(data, sel, {"rms_slope": TABLE_RMS, "n": n, "k": k}, reps, seed) if reps else {}
    allp = [x for v in pulls.values() for x in v]
    return {"kind": "pbsdf", "case": f"{model[0]}/{model[1]}", "generating": f"{model[0]}/{model[1]}",
            "chosen": c.label, "correct": correct((c.shadowing, c.diffuse), model, res.verdict.adequate),
            "adequate": res.verdict.adequate, "misfit": f"M00 {100 * np.sqrt(np.mean(res.rms_m00 ** 2)):.3g} %",
            "rms_slope": res.rms_slope, "n": float(res.n[2]), "k": float(res.k[2]), "errors": res.verdict.errors,
            "pull_std": pull_std(allp), "pulls": len(allp)}


# ---------------------------------------------------------------------------------------------
# 3. tables from Mitsuba's own BSDFs

def mitsuba_table(path, bsdf: dict, resolution=(13, 24, 24)):
    """Tabulate a Mitsuba BSDF (its C++ eval, llvm_ad_spectral_polarized) as a measured_polarized
    table on the exporter's grid: the paper's bases from :func:`eval_paper`, then the table's frames."""
    import mitsuba as mi

    from hyde_bsdf.validation._frames import eval_paper
    from hyde_bsdf.mitsuba.variants import set_variant

    set_variant("llvm_ad_spectral_polarized")
    b = mi.load_dict(bsdf)
    pd, td, th = grids(resolution)
    om_i, om_r, x = rusinkiewicz_to_directions(pd[:, None, None], td[None, :, None], th[None, None, :])
    oi, orr, x = _edge_directions(om_i, om_r, x, edge_deg(td.size))
    _, _, _, pi_, pr = paper_angles(oi, orr)
    s_i = np.stack([-np.sin(pi_), np.cos(pi_), 0 * pi_], -1)
    s_r = np.stack([np.sin(pr), -np.cos(pr), 0 * pr], -1)
    shape = oi.shape[:-1]
    M = np.empty(shape + (len(KAIST_WAVELENGTHS), 4, 4), np.float32)
    for band, wl in enumerate(KAIST_WAVELENGTHS):
        F = eval_paper(b, *(a.reshape(-1, 3) for a in (oi, orr, s_i, s_r)), wavelength=float(wl))
        M[..., band, :, :] = paper_to_table(F.reshape(shape + (4, 4)), oi, orr, x)
    write_pbsdf(path, th, td, pd, KAIST_WAVELENGTHS, M)
    return path


def conductor_case(material, alpha, folder, quick, reps, seed):
    path = mitsuba_table(Path(folder) / f"{material}_{alpha}.pbsdf", {"type": "roughconductor",
                         "distribution": "beckmann", "alpha": alpha, "material": material},
                         (9, 16, 16) if quick else (13, 24, 24))
    data = pbsdf_samples(path, max_points=500 if quick else 1500)
    sel, warned = _quiet(select_model_pbsdf, data, progress=False)
    res = sel.result
    n, k = band_index(material=material)
    rms = alpha / math.sqrt(2)
    err = {"alpha": abs(res.rms_slope / rms - 1), "n": float(np.max(np.abs(res.n / n - 1))),
           "k": float(np.max(np.abs(res.k / k - 1)))}
    exact, _ = _quiet(fit_pbsdf, data, shadowing="smith", diffuse="none", progress=False,
                      start=res.params(data.wavelengths.size // 2))
    classic = exact.verdict.figures["stderr_classic"]["rms_slope"]
    pulls = table_pulls(data, sel_of(exact), {"rms_slope": rms, "n": n, "k": k}, reps, seed, 2e-4, 1e-4)
    return {"case": f"roughconductor {material} alpha {alpha}", "chosen": sel.choice.label,
            "adequate": res.verdict.adequate, "errors": res.verdict.errors,
            "alpha": math.sqrt(2) * res.rms_slope, "alpha_err": err["alpha"], "n_err_max": err["n"],
            "k_err_max": err["k"], "within_target": err["alpha"] <= 0.03 and err["n"] <= 0.05 and err["k"] <= 0.05,
            "warned": bool(warned), "smith_pull_classic": (exact.rms_slope - rms) / classic,
            "smith_pull_reported": (exact.rms_slope - rms) / exact.stderr["rms_slope"],
            "smith_noisy_pull_mean": float(np.mean(pulls["rms_slope"])) if pulls.get("rms_slope") else float("nan"),
            "smith_noisy_pull_std": pull_std(pulls.get("rms_slope", []))}


def sel_of(result):
    """A stand-in selection holding one fixed model's fit (for :func:`table_pulls`)."""
    from types import SimpleNamespace
    return SimpleNamespace(choice=SimpleNamespace(shadowing=result.shadowing, diffuse=result.diffuse,
                                                  dielectric=False), result=result)


def pplastic_case(diffuse_reflectance, folder, quick):
    path = mitsuba_table(Path(folder) / f"pplastic_{diffuse_reflectance}.pbsdf",
                         {"type": "pplastic", "distribution": "beckmann", "alpha": 0.2,
                          "diffuse_reflectance": float(diffuse_reflectance),
                          "int_ior": PPLASTIC_ETA, "ext_ior": 1.0}, (9, 16, 16) if quick else (13, 24, 24))
    data = pbsdf_samples(path, max_points=QUICK_MISFIT_POINTS if quick else 1500)
    sel, warned = _quiet(select_model_pbsdf, data, progress=False)
    res = sel.result
    return {"case": f"pplastic diffuse {diffuse_reflectance}", "chosen": sel.choice.label,
            "adequate": res.verdict.adequate, "errors": res.verdict.errors, "alpha": math.sqrt(2) * res.rms_slope,
            "alpha_err": abs(math.sqrt(2) * res.rms_slope / 0.2 - 1),
            "n_err_max": float(np.max(np.abs(res.n / PPLASTIC_ETA - 1))), "k_err_max": float(np.max(res.k)),
            "within_target": "", "warned": bool(warned), "smith_pull_classic": "", "smith_pull_reported": "",
            "smith_noisy_pull_mean": "", "smith_noisy_pull_std": ""}, (data, res, warned)


# ---------------------------------------------------------------------------------------------
# 4. silent misfits

def misfit_beyond_tolerance(res):
    return (float(np.sqrt(np.mean(res.rms_m00 ** 2))) > M00_TOLERANCE
            or float(np.sqrt(np.mean(res.rms_elements ** 2))) > ELEMENT_TOLERANCE)


def silent_misfits(folder, quick):
    """The issue's wrong fits with a fixed model; returns rows (case, misfit, warned, silent)."""
    rows = []
    au = mitsuba_table(Path(folder) / "silent_au.pbsdf", {"type": "roughconductor", "distribution": "beckmann",
                       "alpha": 0.2, "material": "Au"}, (9, 16, 16) if quick else (13, 24, 24))
    diel = Path(folder) / "silent_diel.pbsdf"
    export_pbsdf(diel, rms_slope=0.3, n=1.5, k=0.0, shadowing="vgroove", diffuse="paper",
                 resolution=(9, 16, 16), error_samples=0, alpha_sample=0.3)
    for label, path, opts in [("default vgroove/paper on a Smith conductor (Mitsuba Au)", au, {}),
                              ("dielectric with a diffuse term fitted with diffuse none", diel,
                               {"diffuse": "none", "shadowing": "vgroove"})]:
        data = pbsdf_samples(path, max_points=QUICK_MISFIT_POINTS if quick else 1500)
        res, warned = _quiet(fit_pbsdf, data, progress=False, **opts)
        rows.append(_silent_row(label, res, warned))
    return rows


def _silent_row(label, res, warned):
    bad = misfit_beyond_tolerance(res)
    return {"case": label, "M00_misfit_pct": 100 * float(np.sqrt(np.mean(res.rms_m00 ** 2))),
            "elements_misfit": float(np.sqrt(np.mean(res.rms_elements ** 2))), "beyond_tolerance": bad,
            "warned": bool(warned), "silent": bad and not warned}


# ---------------------------------------------------------------------------------------------
# the report

def validate(outdir="out/validation", quick=False):
    """Run parts 1-4, write the PNG and CSV files, return the checks.  ``quick``: 4 CSV models with
    8 noise realizations, 2 table models (one with 4 noisy refits), Au alpha 0.3 and pplastic with a
    diffuse base on a coarse grid; the full run: every case (1500 geometries), 30 (CSV), 8 (tables) or
    6 (Mitsuba conductors) noise realizations, refitting 600 geometries."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    reps = 8 if quick else 30
    clock = time.perf_counter()
    csv_models = [("vgroove", "paper"), ("smith", "none"), ("none", "paper"), ("smith", "reciprocal")] \
        if quick else MODELS
    cases = [csv_case(m, reps, 100 + i) for i, m in enumerate(csv_models)]
    print(f"[fit_model_selection] CSV cases {time.perf_counter() - clock:.0f} s", file=sys.stderr)
    table_models = [("vgroove", "paper"), ("smith", "none")] if quick else MODELS
    conductors = [("Au", 0.3)] if quick else CONDUCTORS
    with tempfile.TemporaryDirectory() as folder:
        cases += [table_case(m, folder, quick, (4 if quick and i == 0 else 0 if quick else 8), 200 + i)
                  for i, m in enumerate(table_models)]
        print(f"[fit_model_selection] + tables {time.perf_counter() - clock:.0f} s", file=sys.stderr)
        mits = [conductor_case(mat, a, folder, quick, 3 if quick else 6, 300 + i)
                for i, (mat, a) in enumerate(conductors)]
        plastics = [pplastic_case(d, folder, quick) for d in ((0.5,) if quick else (0.0, 0.5))]
        mits += [row for row, _ in plastics]
        print(f"[fit_model_selection] + Mitsuba tables {time.perf_counter() - clock:.0f} s", file=sys.stderr)
        silent = silent_misfits(folder, quick)
        silent += [_silent_row(f"pplastic diffuse {d}: chosen model", res, w)
                   for d, (_, (_, res, w)) in zip((0.5,) if quick else (0.0, 0.5), plastics)]
    write_csv(out / "fit_model_selection.csv", list(cases[0]), [list(c.values()) for c in cases])
    write_csv(out / "fit_model_selection_mitsuba.csv", list(mits[0]), [list(m.values()) for m in mits])
    write_csv(out / "fit_model_selection_silent.csv", list(silent[0]), [list(r.values()) for r in silent])
    _plot(out / "fit_model_selection.png", cases, mits)
    return _checks(cases, mits, silent)


def _checks(cases, mits, silent):
    wrong = [f"{c['kind']} {c['case']} -> {c['chosen']}" for c in cases if not c["correct"]]
    cond = [m for m in mits if m["case"].startswith("roughconductor")]
    claimed = [c for c in cases if c["pulls"] and c["errors"] != "lower bounds"]
    bad_pulls = [f"{c['kind']} {c['case']} {c['pull_std']:.3g}" for c in claimed
                 if not PULL_RANGE[0] <= c["pull_std"] <= PULL_RANGE[1]]
    noisy = [m for m in cond if math.isfinite(m["smith_noisy_pull_std"])]
    outside = [m for m in mits if m["case"] == "pplastic diffuse 0.5"]
    return [
        dict(name="model chosen: the generating one or an adequate smaller one", value=f"{len(cases) - len(wrong)}/"
             f"{len(cases)}" + (f" (wrong: {'; '.join(wrong)})" if wrong else ""), tolerance="all", passed=not wrong),
        dict(name="Mitsuba roughconductor, default (auto): alpha within 3 %, n, k within 5 % in every band",
             value="; ".join(f"{m['case']}: {m['chosen']} alpha {100 * m['alpha_err']:.2g} %, n {100 * m['n_err_max']:.2g} %, "
                             f"k {100 * m['k_err_max']:.2g} %" for m in cond), tolerance="3 % / 5 %",
             passed=all(m["within_target"] for m in cond)),
        dict(name="silent misfits (misfit beyond the tolerance without a warning)",
             value=f"{sum(r['silent'] for r in silent)} of {sum(r['beyond_tolerance'] for r in silent)} misfits",
             tolerance="0", passed=not any(r["silent"] for r in silent)),
        dict(name="pplastic with a diffuse base (outside the model) is warned",
             value=", ".join(f"{m['chosen']} warned={m['warned']}" for m in outside), tolerance="warned",
             passed=all(m["warned"] or m["adequate"] for m in outside)),
        dict(name="pull std of the claimed standard errors", value=", ".join(
             f"{c['kind']} {c['case']} {c['pull_std']:.3g}" for c in claimed), tolerance=f"{PULL_RANGE}",
             passed=not bad_pulls),
        dict(name="rational vs exact Smith (Mitsuba conductors): |pull| of alpha, classic -> reported errors; "
             "noisy pull mean, std", value="; ".join(f"{m['case']}: {abs(m['smith_pull_classic']):.3g} -> "
                                              f"{abs(m['smith_pull_reported']):.3g}; {m['smith_noisy_pull_mean']:.3g}, "
                                              f"{m['smith_noisy_pull_std']:.3g}"
                                              for m in cond),
             tolerance="reported |pull| <= 3; noisy: |mean pull| <= 2, pull std <= 1.25",
             passed=all(abs(m["smith_pull_reported"]) <= 3 for m in cond)
             and all(m["smith_noisy_pull_std"] <= PULL_RANGE[1] and abs(m["smith_noisy_pull_mean"]) <= 2
                     for m in noisy)),
    ]


def _plot(path, cases, mits):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    ax = axes[0]
    size = lambda label: model_size(*label.split(" ")[0].split("/"), 0) - (0.2 if "k=0" in label else 0)
    for i, c in enumerate(cases):
        ax.plot(i, size(c["generating"]), "ks", mfc="none", ms=9)
        ax.plot(i, size(c["chosen"]), "o", color="C2" if c["correct"] else "C3", ms=6)
    ax.set_xticks(range(len(cases)), [f"{c['kind']}\n{c['case']}" for c in cases], rotation=90, fontsize=6)
    ax.set_ylabel("model terms (shadowing + diffuse)")
    ax.set_title("generating (square) and chosen (dot: green = correct)", fontsize=9)
    ax = axes[1]
    cond = [m for m in mits if m["case"].startswith("roughconductor")]
    x = np.arange(len(cond))
    for j, (key, lab) in enumerate((("alpha_err", "alpha"), ("n_err_max", "n (worst band)"), ("k_err_max", "k (worst band)"))):
        ax.bar(x + 0.27 * (j - 1), [max(m[key], 1e-7) for m in cond], 0.27, label=lab)
    ax.axhline(0.03, color="k", ls="--", lw=0.8)
    ax.axhline(0.05, color="k", ls=":", lw=0.8)
    ax.set_yscale("log")
    ax.set_xticks(x, [f"{m['case'].replace('roughconductor ', '')}\n{m['chosen']}" for m in cond], fontsize=7)
    ax.set_title("Mitsuba roughconductor tables, default command: relative errors (3 %, 5 % lines)", fontsize=9)
    ax.legend(fontsize=7)
    ax = axes[2]
    claimed = [c for c in cases if c["pulls"]]
    ax.bar(range(len(claimed)), [c["pull_std"] for c in claimed], color="C0")
    ax.axhspan(*PULL_RANGE, color="C2", alpha=0.15)
    ax.set_xticks(range(len(claimed)), [f"{c['kind']}\n{c['case']}" for c in claimed], rotation=90, fontsize=6)
    ax.set_ylabel("pull std over repeated noise")
    ax.set_title("standard errors: pull std (target 0.8-1.25)", fontsize=9)
    save_figure(fig, path, dpi=110, tight=True)


if __name__ == "__main__":
    cli(validate, __doc__)
