"""Fitting n, k, rms_slope to synthetic Mueller measurements like the paper's Figs. 8-9.

1. Synthetic data from the model (paper Eq. 17, V-groove shadowing, paper diffuse
   term) in the specular plane, theta_i = theta_r = 10, 20, ..., 80 deg, elements
   M01, M11, M22, M23 over M00; each value the mean of 256 single measurements with
   Gaussian noise (sigma_1 = 0.03 per measurement; the bars are +-1 sigma of the 256,
   as in the paper), for LabSphere Infragold (eta = 0.285 - j7.3523, rms_slope 0.44)
   and flame-sprayed aluminium (eta = 1.226 - j10.413, rms_slope 0.43).  Fit all three
   parameters from the default multi-start; report values, standard errors, pulls
   (fit - truth) / stderr, correlations, chi^2.  Plots like Figs. 8-9.
2. Coverage: 200 noise realizations per material; mean and spread of the pulls
   (both should be ~0 and ~1 if the standard errors are right).
3. Ill-posedness: the n-k correlation and the relative errors of n and k against the
   angular range used (10 deg .. theta_max, 8 angles), with all four elements and
   with M01, M11 only (no phase information: the M22/M23 pair is what an
   ellipsometer uses); and "too few angles" cases (refused / warned).
5. A large measurement file (10^6 random geometries, 4 elements, 100 MB; 10^5 in quick mode):
   the time to read it and to fit n, k, rms_slope from the default multi-start.

Writes to OUTDIR (default out/validation/): fit_synthetic_<material>.png/.csv (the
measurement CSV in the reader's format), fit_synthetic.csv (fit results),
fit_coverage.csv, fit_correlation.png/.csv, fit_too_few.csv, fit_large.csv.

    python hyde_bsdf/validation/fit_synthetic.py [-o OUTDIR] [--trials 200]
"""
from __future__ import annotations

import argparse
import csv
import sys
import warnings
from pathlib import Path

import numpy as np

from hyde_bsdf.fit import IllPosedFitWarning, fit_measurements, fit_mueller, synthetic_measurements
from hyde_bsdf.app.plots import plot_fit
from hyde_bsdf.io.measurements import write_measurements
from hyde_bsdf.io.atomic import atomic_open

from hyde_bsdf.validation._common import FIGURES, cli, save_figure  # noqa: E402

MATERIALS = {
    "infragold": {"n": 0.285, "k": 7.3523, "rms_slope": 0.44, "label": "LabSphere Infragold (Fig. 8)"},
    "fsa": {"n": 1.226, "k": 10.413, "rms_slope": 0.43, "label": "flame-sprayed aluminium (Fig. 9)"},
}
ELEMENTS = ("M01", "M11", "M22", "M23")
ANGLES_DEG = np.arange(10.0, 81.0, 10.0)
NOISE = 0.03
N_SAMPLES = 256
PARAMS = ("n", "k", "rms_slope")


def truth_of(m):
    return {q: MATERIALS[m][q] for q in PARAMS}


def validate(outdir="out/validation", quick=False, trials=200, large_rows=None):
    """Run parts 1-5; write the PNG/CSV files; return the report's checks.

    ``quick``: 30 noise realizations instead of ``trials``, theta_max every 15 deg, a large file
    of 10^5 rows instead of ``large_rows`` (default 10^6).
    """
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    th = np.radians(ANGLES_DEG)
    if quick:
        trials = 30

    # ---- 1. one realization per material, fitted from the default multi-start
    rows = []
    for m, mat in MATERIALS.items():
        truth = truth_of(m)
        meas = synthetic_measurements(th, th, np.pi, ELEMENTS, **truth, noise=NOISE, n_samples=N_SAMPLES,
                                      rng=20091123)
        write_measurements(out / f"fit_synthetic_{m}.csv", meas,
                           comments=[f"synthetic {mat['label']}: eta = {truth['n']} - j{truth['k']}, "
                                     f"rms_slope = {truth['rms_slope']}; means of {N_SAMPLES} samples, "
                                     f"single-sample noise {NOISE}"])
        res = fit_measurements(meas, fit=PARAMS, rms_slope=0.3)
        print(f"\n== {mat['label']}\n{res.summary()}")
        plot_fit(res, meas, out / f"fit_synthetic_{m}.png", truth=truth,
                 title=f"synthetic {mat['label']}: truth eta = {truth['n']} - j{truth['k']}, "
                       f"rms_slope = {truth['rms_slope']} (bars: +-1 sigma of {N_SAMPLES} samples)")
        FIGURES.append(str(out / f"fit_synthetic_{m}.png"))     # saved by app.plots: named for the report here
        for q in PARAMS:
            pull = (res.params[q] - truth[q]) / res.stderr[q]
            rows.append({"material": m, "parameter": q, "truth": truth[q], "fit": res.params[q],
                         "stderr": res.stderr[q], "pull": pull, "within_2sigma": abs(pull) <= 2,
                         "chi2": res.chi2, "dof": res.dof, "reduced_chi2": res.reduced_chi2,
                         "corr_n_k": res.correlation_of("n", "k"),
                         "corr_n_rms": res.correlation_of("n", "rms_slope"),
                         "corr_k_rms": res.correlation_of("k", "rms_slope"),
                         "converged": res.success})
    _write(out / "fit_synthetic.csv", rows)

    # ---- 2. coverage of the standard errors
    cov_rows = []
    rng = np.random.default_rng(1)
    for m in MATERIALS:
        truth = truth_of(m)
        pulls = {q: [] for q in PARAMS}
        chi2s = []
        for t in range(trials):
            meas = synthetic_measurements(th, th, np.pi, ELEMENTS, **truth, noise=NOISE,
                                          n_samples=N_SAMPLES, rng=rng)
            # start away from the truth (one start: the multi-start is tested above)
            r = fit_measurements(meas, fit=PARAMS, rms_slope=0.3, n0=1.0, k0=5.0)
            for q in PARAMS:
                pulls[q].append((r.params[q] - truth[q]) / r.stderr[q])
            chi2s.append(r.reduced_chi2)
            if (t + 1) % 20 == 0 or t + 1 == trials:
                print(f"\r[coverage] {m}: {t + 1}/{trials}", end="", file=sys.stderr, flush=True)
        print(file=sys.stderr)
        for q in PARAMS:
            p = np.array(pulls[q])
            cov_rows.append({"material": m, "parameter": q, "trials": trials, "pull_mean": p.mean(),
                             "pull_std": p.std(ddof=1), "frac_within_1sigma": np.mean(np.abs(p) <= 1),
                             "frac_within_2sigma": np.mean(np.abs(p) <= 2),
                             "mean_reduced_chi2": float(np.mean(chi2s))})
    _write(out / "fit_coverage.csv", cov_rows)
    print("\ncoverage of the standard errors (pull = (fit - truth) / stderr):")
    for r in cov_rows:
        print(f"  {r['material']:9s} {r['parameter']:9s} pull mean {r['pull_mean']:+.3f}, std "
              f"{r['pull_std']:.3f}, |pull|<=1: {100 * r['frac_within_1sigma']:.0f} %, "
              f"<=2: {100 * r['frac_within_2sigma']:.0f} %")

    # ---- 3. correlation against the angular range
    corr_rows = []
    tmax = np.arange(20.0, 81.0, 15.0) if quick else np.arange(15.0, 81.0, 5.0)
    sets = {"M01,M11,M22,M23": ELEMENTS, "M01,M11": ("M01", "M11")}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IllPosedFitWarning)   # recorded in the CSV instead
        for m in MATERIALS:
            truth = truth_of(m)
            for sname, els in sets.items():
                for hi in tmax:
                    a = np.radians(np.linspace(10.0, hi, 8))
                    # noiseless data at the truth: the Jacobian there gives the expected covariance
                    model = fit_mueller(a, a, np.pi, {e: _model(a, e, truth) for e in els},
                                        sigma={e: np.full(a.size, NOISE / np.sqrt(N_SAMPLES)) for e in els},
                                        fit=PARAMS, rms_slope=truth["rms_slope"], n0=truth["n"],
                                        k0=truth["k"])
                    corr_rows.append({"material": m, "elements": sname, "theta_min_deg": 10.0,
                                      "theta_max_deg": hi, "corr_n_k": model.correlation_of("n", "k"),
                                      "rel_err_n": model.stderr["n"] / truth["n"],
                                      "rel_err_k": model.stderr["k"] / truth["k"],
                                      "rel_err_rms_slope": model.stderr["rms_slope"] / truth["rms_slope"],
                                      "condition_number": model.condition_number,
                                      "warnings": " | ".join(model.warnings)})
    _write(out / "fit_correlation.csv", corr_rows)
    _plot_correlation(corr_rows, out / "fit_correlation.png")

    # ---- 4. too few angles
    few = []
    truth = truth_of("infragold")
    cases = [
        ("1 angle (45 deg), M01 only, fit n,k,rms_slope", [45.0], ("M01",)),
        ("2 angles (10, 15 deg), M01, M11, fit n,k,rms_slope", [10.0, 15.0], ("M01", "M11")),
        ("3 angles (10-20 deg), all 4 elements, fit n,k,rms_slope", [10.0, 15.0, 20.0], ELEMENTS),
        ("1 angle (60 deg), M01, M22, M23 (ellipsometry), fit n,k", [60.0], ("M01", "M22", "M23")),
    ]
    for label, angles, els in cases:
        a = np.radians(angles)
        meas = synthetic_measurements(a, a, np.pi, els, **truth, noise=NOISE, n_samples=N_SAMPLES, rng=3)
        fitp = ("n", "k") if "fit n,k" in label and "rms" not in label else PARAMS
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                r = fit_measurements(meas, fit=fitp, rms_slope=truth["rms_slope"] if len(fitp) == 2 else 0.3)
                outcome = "warned" if r.warnings else "accepted"
                text = " | ".join(r.warnings) or (f"n = {r.params['n']:.4g} +- {r.stderr['n']:.2g}, "
                                                  f"k = {r.params['k']:.4g} +- {r.stderr['k']:.2g}")
            except ValueError as exc:
                outcome, text = "refused", str(exc)
        few.append({"case": label, "outcome": outcome, "message": text,
                    "warnings_issued": len([c for c in caught if issubclass(c.category, IllPosedFitWarning)])})
        print(f"\n[{outcome}] {label}\n    {text}")
    _write(out / "fit_too_few.csv", few)
    print(f"\nwrote {out}/fit_*.png/csv")
    checks = []
    for r in rows:
        checks.append(dict(name=f"{r['material']}: {r['parameter']} fitted (truth {r['truth']:g}); pull (fit - truth)/se",
                           value=f"{r['fit']:.5g} +- {r['stderr']:.2g}, pull {r['pull']:+.2f}", tolerance="|pull| < 3",
                           passed=abs(r["pull"]) < 3))
    lo, hi = (0.6, 1.4) if quick else (0.8, 1.2)
    for r in cov_rows:
        checks.append(dict(name=f"{r['material']}: {r['parameter']}, spread of the pulls over {trials} noise "
                                f"realizations (standard errors right)",
                           value=f"{r['pull_std']:.3f} (mean {r['pull_mean']:+.3f})", tolerance=f"[{lo}, {hi}]",
                           passed=lo <= r["pull_std"] <= hi))
    full = [r for r in corr_rows if r["elements"] == "M01,M11,M22,M23"]
    part = [r for r in corr_rows if r["elements"] == "M01,M11"]
    worst_full = max(abs(r["corr_n_k"]) for r in full)
    least_part = min(r["corr_n_k"] for r in part)
    checks.append(dict(name="n-k correlation with M22, M23 (any angular range, both materials)",
                       value=f"max |rho| = {worst_full:.2g}", tolerance="< 0.05", passed=worst_full < 0.05))
    checks.append(dict(name="n-k correlation with M01, M11 only (any angular range): ill-posed, reported",
                       value=f"min rho = {least_part:.4f}", tolerance="> 0.95", passed=least_part > 0.95))
    expected = ["refused", "warned", "warned", "accepted"]
    for f, e in zip(few, expected):
        checks.append(dict(name=f"too few angles: {f['case']}", value=f["outcome"], tolerance=e,
                           passed=f["outcome"] == e))

    # ---- 5. a large measurement file: read and fit time
    large = large_file(out, rows=100_000 if quick else 1_000_000 if large_rows is None else large_rows)
    r = large
    checks.append(dict(name=f"large file: {r['rows']} geometries x 4 elements read + fitted (n, k, rms_slope, "
                            f"default multi-start) in (s)",
                       value=f"{r['total_seconds']:.1f} (read {r['read_seconds']:.1f}, fit {r['fit_seconds']:.1f})",
                       tolerance="< 60", passed=r["total_seconds"] < 60))
    checks.append(dict(name=f"large file: fitted parameters within 4 standard errors of the truth",
                       value=f"max |pull| = {r['max_pull']:.2f}", tolerance="< 4", passed=r["max_pull"] < 4))
    return checks


def large_file(out, rows=1_000_000, seed=4):
    """Part 5: ``rows`` random geometries (theta 5-80 deg, any phi) of Infragold, M01, M11, M22, M23
    with noise 0.01, written as a CSV in a temporary folder; time ``read_measurements`` and
    ``fit_measurements`` (n, k, rms_slope from the default multi-start).  Writes fit_large.csv."""
    import os
    import tempfile
    import time

    from hyde_bsdf.fit import mueller_elements
    from hyde_bsdf.io.measurements import read_measurements

    rng = np.random.default_rng(seed)
    truth = truth_of("infragold")
    ti, tr = np.radians(rng.uniform(5, 80, (2, rows)))
    ph = np.radians(rng.uniform(0, 360, rows))
    model = mueller_elements(ti, tr, ph, ELEMENTS, **truth)
    cols = [np.degrees(ti), np.degrees(tr), np.degrees(ph)]
    header = "theta_i_deg,theta_r_deg,phi_deg"
    for e in ELEMENTS:
        cols += [model[e] + 0.01 * rng.standard_normal(rows), np.full(rows, 0.01)]
        header += f",{e},{e}_sigma"
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "large.csv")
        np.savetxt(path, np.column_stack(cols), delimiter=",", fmt="%.9g", header=header, comments="")
        del cols, model
        size = os.path.getsize(path)
        t0 = time.perf_counter()
        meas = read_measurements(path, progress=True)
        t1 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", IllPosedFitWarning)
            res = fit_measurements(meas, fit=PARAMS, rms_slope=0.3)
        t2 = time.perf_counter()
    pulls = {q: (res.params[q] - truth[q]) / res.stderr[q] for q in PARAMS}
    row = {"rows": rows, "file_mb": size / 1e6, "read_seconds": t1 - t0, "fit_seconds": t2 - t1,
           "total_seconds": t2 - t0, "model_evaluations": res.nfev, "reduced_chi2": res.reduced_chi2,
           **{f"{q}_fit": res.params[q] for q in PARAMS}, **{f"{q}_pull": pulls[q] for q in PARAMS},
           "max_pull": max(abs(v) for v in pulls.values()), "load_average": os.getloadavg()[0]}
    _write(out / "fit_large.csv", [row])
    print(f"\nlarge file: {rows} rows ({size / 1e6:.0f} MB): read {t1 - t0:.1f} s, fit {t2 - t1:.1f} s "
          f"(load average {row['load_average']:.1f}); pulls "
          + ", ".join(f"{q} {v:+.2f}" for q, v in pulls.items()))
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("-o", "--outdir", default="out/validation")
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--quick", action="store_true", help="the report's quick mode")
    ap.add_argument("--large-rows", type=int, default=None, help="rows of the large-file timing (default 10^6)")
    args = ap.parse_args(argv)
    checks = validate(args.outdir, quick=args.quick, trials=args.trials, large_rows=args.large_rows)
    for c in checks:
        print(f"[{'pass' if c['passed'] else 'FAIL'}] {c['name']}: {c['value']} (tolerance {c['tolerance']})")
    return 0 if all(c["passed"] for c in checks) else 1


def _model(a, element, truth):
    from hyde_bsdf.fit import mueller_elements

    return mueller_elements(a, a, np.pi, (element,), **truth)[element]


def _plot_correlation(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for c, m in enumerate(MATERIALS):
        for ls, sname in (("-", "M01,M11,M22,M23"), ("--", "M01,M11")):
            sel = [r for r in rows if r["material"] == m and r["elements"] == sname]
            x = [r["theta_max_deg"] for r in sel]
            lab = f"{m}, {sname}"
            axes[0].plot(x, [r["corr_n_k"] for r in sel], f"C{c}{ls}", label=lab)
            axes[1].semilogy(x, [r["rel_err_n"] for r in sel], f"C{c}{ls}", label=lab)
            axes[2].semilogy(x, [r["rel_err_k"] for r in sel], f"C{c}{ls}", label=lab)
    axes[0].set_title("correlation(n, k)")
    axes[1].set_title("relative standard error of n")
    axes[2].set_title("relative standard error of k")
    for a in axes:
        a.set_xlabel(r"$\theta_{max}$ (deg): 8 angles from 10 deg to $\theta_{max}$, $\theta_i=\theta_r$")
        a.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"expected fit uncertainty (Jacobian at the truth; noise {NOISE}/sqrt({N_SAMPLES}) per value); "
                 "missing points: singular Jacobian", fontsize=9)
    # the margins tight_layout chose for these labels, fixed: it measured every tick label again (~0.3 CPU s)
    fig.subplots_adjust(left=0.033, right=0.989, bottom=0.146, top=0.837, wspace=0.142)
    save_figure(fig, path, dpi=110)


def _write(path, rows):
    with atomic_open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


if __name__ == "__main__":
    cli(validate, __doc__, main)
