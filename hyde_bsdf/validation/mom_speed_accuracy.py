"""Speed against accuracy of the two-region (lossy) MoM (issue 11, part 4).

Two sweeps, CPU seconds (summed over workers, process time) against error, the
defaults marked:

* points per wavelength (6-20; default 10) on an Infragold flat plate (100 lambda,
  theta_i = 60 deg, both polarisations): the error is the largest of |R_s - |r_s|^2|,
  |R_p - |r_p|^2| and |arg(r_p/r_s) error| / 100 deg (so 0.5 deg counts as 0.005).  The
  interior Green's function of the metal is integrated with one quadrature panel per
  decay length (skin depth / 2 pi) automatically, so the skin depth sets the cost of
  the fill, not the number of unknowns.
* partitions (2-16, 100 lambda each; the Fig. 6 default is 100 of 150 lambda) on the
  Infragold surface of Figs. 8-9 (rms slope 0.44, ell = 5 lambda, theta_i = 45 deg): the
  error is the median relative standard error of M00 over the lobe (speckle), which falls
  as 1/sqrt(M) while the cost grows as M.
* the solver (issue 17): the Fig. 6 surface (PEC, 150-lambda partitions of 1500 unknowns,
  both polarisations, theta_i = 10, 45, 75 deg) by the dense LU and by the fast solver
  (forward-backward sweeps with spectral acceleration) at residual tolerances 1e-2 .. 1e-6
  (default 1e-4): the error is the fast M00's rms dB difference from the dense one over the
  lobe (the dense LU is exact for the discretised equations; its cost is the dashed line).
  Measured (4 partitions): 3e-3 dB at 1e-2, 5e-4 at 1e-3, 7e-5 dB from 1e-4 on (the far
  cells' integration: exact per plane wave in the fast operator, linearised phase in the
  dense one); the fast solver's set-up, not its iterations, sets its cost, about an eighth
  of the dense path's (0.74 against 5.8 CPU s at the default).

Writes mom_speed_accuracy.png and .csv (with the fill / LU / far-field split of each run).
"""
import math
import warnings
from pathlib import Path

import numpy as np

from hyde_bsdf.validation._common import cli, save_figure, write_csv  # noqa: E402

N_AU, K_AU = 0.285, 7.3523


def cpu(res):
    t = res.times
    return t["fill"] + t["factor"] + t["solve"] + t["far_field"]


def ppw_sweep(quick):
    from hyde_bsdf import mom
    from hyde_bsdf.model.fresnel import fresnel_rs_rp

    rs, rp = fresnel_rs_rp(np.cos(np.radians([60.0])), N_AU, K_AU)
    rows = []
    for ppw in ([6, 10, 14] if quick else [6, 8, 10, 14, 20]):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", mom.MoMAccuracyWarning)  # 6 pts/lambda is meant to be coarse
            res = mom.scatter(100.0, 1, 0.0, 1.0, [60.0], [60.0], pts_per_wl=ppw, executor=mom.SerialExecutor(),
                              polarization=("s", "p"), n=N_AU, k=K_AU, progress=False)
        ph = abs(math.degrees(np.angle(res.sigma_sp[0, 0] * (rp[0] / rs[0]))))
        err = max(abs(res.power_balance_s[0] - abs(rs[0]) ** 2), abs(res.power_balance_p[0] - abs(rp[0]) ** 2),
                  ph / 100.0)
        t = res.times
        rows.append(["pts_per_wl", ppw, err, cpu(res), t["fill"], t["factor"], t["far_field"]])
    return rows


def partition_sweep(quick):
    from hyde_bsdf import mom
    from hyde_bsdf.mom import model1d

    ell, slope = 5.0, 0.44
    tr = np.arange(-89.0, 89.01, 1.0)
    lobe_model = model1d.mueller_sigma(np.radians([45.0])[:, None], np.radians(tr), slope, N_AU, K_AU)["M00"][0]
    lobe = lobe_model >= 0.1 * lobe_model.max()
    rows = []
    for parts in ([2, 4] if quick else [2, 4, 8, 16]):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", mom.MoMAccuracyWarning)
            res = mom.scatter(100.0 * parts, parts, slope * ell / math.sqrt(2.0), ell, [45.0], tr, pts_per_wl=10,
                              seed=5, executor=mom.SerialExecutor(), polarization=("s", "p"), n=N_AU, k=K_AU,
                              progress=False)
        rel = res.mueller_std_error["M00"][0][lobe] / res.mueller["M00"][0][lobe]
        t = res.times
        rows.append(["partitions", parts, float(np.median(rel)), cpu(res), t["fill"], t["factor"], t["far_field"]])
    return rows


def solver_sweep(quick):
    """Fast solver at several tolerances against the dense LU on the Fig. 6 surface (CPU seconds, M00 dB)."""
    from hyde_bsdf import mom
    from hyde_bsdf.mom.fast import FAST_TOL

    ell = 5.0
    parts = 1 if quick else 4
    ti = [45.0, 75.0] if quick else [10.0, 45.0, 75.0]
    args = (150.0 * parts, parts, 0.3 * ell / math.sqrt(2.0), ell, ti, np.arange(-89.0, 89.01, 1.0))
    kw = dict(pts_per_wl=10, seed=0, executor=mom.SerialExecutor(), polarization=("s", "p"), progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mom.MoMAccuracyWarning)   # quick: one partition is short of speckle
        dense = mom.scatter(*args, solver="dense", **kw)
        m = dense.mueller["M00"]
        lobe = m >= 0.1 * m.max(axis=1, keepdims=True)
        rows = [["solver", "dense", 0.0, cpu(dense), dense.times["fill"], dense.times["factor"],
                 dense.times["far_field"]]]
        for tol in ([1e-2, 1e-4, 1e-6] if quick else [1e-2, 3e-3, 1e-3, 1e-4, 1e-5, 1e-6]):
            res = mom.scatter(*args, solver="fast", tol=tol, **kw)
            db = 10 * np.log10(res.mueller["M00"][lobe] / m[lobe])
            t = res.times
            rows.append(["solver", f"fast {tol:g}" + (" (default)" if tol == FAST_TOL else ""),
                         float(np.sqrt(np.mean(db ** 2))), cpu(res), t["fill"], t["solve"], t["far_field"]])
    return rows


def validate(outdir="out/validation", quick=False):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    a, b, c = ppw_sweep(quick), partition_sweep(quick), solver_sweep(quick)
    write_csv(out / "mom_speed_accuracy.csv", ["sweep", "value", "error", "cpu_s", "fill_s", "lu_s_or_iterations_s",
                                               "far_field_s"], a + b + c)
    fig, axes = plt.subplots(1, 3, figsize=(15, 3.8))
    ax = axes[2]
    fast_rows = c[1:]
    ax.loglog([r[3] for r in fast_rows], [max(r[2], 1e-6) for r in fast_rows], "o-", label="fast (tolerance)")
    for r in fast_rows:
        ax.annotate(r[1].split()[1], (r[3], max(r[2], 1e-6)), fontsize=7, xytext=(3, 3), textcoords="offset points")
        if "default" in r[1]:
            ax.plot(r[3], max(r[2], 1e-6), "r*", ms=12, label="default (1e-4)")
    ax.axvline(c[0][3], color="k", ls="--", label="dense LU (exact for the discretisation)")
    ax.set(xlabel="CPU seconds (solve + far field)", ylabel="M00 rms dB from the dense LU (lobe)",
           title="solver: fast tolerance vs dense (Fig. 6 surface, s + p)")
    ax.legend(fontsize=7)
    for ax, rows, title, default in ((axes[0], a, "points per wavelength (Infragold flat plate, 60 deg)", 10),
                                     (axes[1], b, "partitions of 100 lambda (Infragold, slope 0.44, 45 deg)", None)):
        ax.loglog([r[3] for r in rows], [r[2] for r in rows], "o-")
        for r in rows:
            ax.annotate(f"{r[1]:g}", (r[3], r[2]), fontsize=7, xytext=(3, 3), textcoords="offset points")
            if r[1] == default:
                ax.plot(r[3], r[2], "r*", ms=12, label=f"default ({default})")
        ax.set(xlabel="CPU seconds (fill + LU + far field)", title=title)
        if default is not None:
            ax.legend(fontsize=7)
    axes[0].set_ylabel("max(|dR_s|, |dR_p|, |d phase|/100 deg)")
    axes[1].set_ylabel("median rel. std error of M00 (lobe)")
    fig.suptitle("MoM, both polarisations, finite index: time against error", fontsize=9)
    # the margins tight_layout chose for these labels, fixed: it measured every tick label again (~0.3 CPU s)
    fig.subplots_adjust(left=0.068, right=0.99, bottom=0.16, top=0.828, wspace=0.26)
    save_figure(fig, out / "mom_speed_accuracy.png")
    d = next(r for r in a if r[1] == 10)
    slope_rows = [r for r in b]
    ratio = slope_rows[-1][2] / slope_rows[0][2]
    expect = math.sqrt(slope_rows[0][1] / slope_rows[-1][1])
    default = next(r for r in c if "default" in r[1])
    return [dict(name="MoM speed/accuracy: fast solver at its default tolerance against the dense LU, M00 rms dB "
                      "over the lobe (Fig. 6 surface, s + p)", value=f"{default[2]:.2e} dB", tolerance=0.05,
                 passed=default[2] <= 0.05),
            dict(name="MoM speed/accuracy: fast / dense CPU seconds on 1500-unknown partitions (s + p, same process)",
                 value=f"{default[3] / c[0][3]:.2f} ({default[3]:.1f} s / {c[0][3]:.1f} s)", tolerance="< 1",
                 passed=default[3] < c[0][3]),
            dict(name="MoM speed/accuracy: flat Infragold error at the default 10 pts/lambda (60 deg)",
                 value=f"{d[2]:.4f} in {d[3]:.1f} CPU s (fill {d[4]:.1f}, LU {d[5]:.1f}, far field {d[6]:.1f})",
                 tolerance=0.01, passed=d[2] <= 0.01),
            dict(name="MoM speed/accuracy: speckle error falls as 1/sqrt(partitions) (ratio vs expected)",
                 value=f"{ratio:.2f} vs {expect:.2f}", tolerance="within a factor 1.6",
                 passed=expect / 1.6 <= ratio <= expect * 1.6)]


if __name__ == "__main__":
    cli(validate, __doc__)
