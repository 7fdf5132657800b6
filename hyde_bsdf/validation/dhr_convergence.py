"""Convergence of the specular DHR (paper Eqs. 14-16) and accuracy of its shipped table.

1. Quadrature error against Gauss-Legendre nodes per piece, and against run time, for the
   three shadowing models at hard points (narrow lobes, grazing incidence).
2. Table interpolation error over the table's whole range, theta_i 0-90 deg and rms_slope
   1e-4 .. 100 (bicubic in (x, ln s), x = 1 - sqrt(cos theta)) against direct quadrature, as a
   map against 90 deg - theta_i (log) and rms_slope, and per decade of rms_slope (the issue's
   target: <= 2e-4 over 1e-4 .. 50, the plugin's range, including near-mirror grazing).
3. Table resolution (uniform grids and the default refined one) against build time and worst
   interpolation error.

Writes dhr_convergence.png/.csv, dhr_table_error.png/.csv, dhr_table_error_by_decade.csv,
dhr_table_resolution.png/.csv into OUTDIR.
"""
import math
import time
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from hyde_bsdf.validation._common import cli, save_figure, write_csv  # noqa: E402

from hyde_bsdf.model import dhr
from hyde_bsdf.model.terms import SHADOWING

POINTS = [(0.0, 0.01), (45.0, 0.3), (80.0, 0.05), (89.0, 0.5), (89.9, 0.01), (60.0, 3.0)]


def convergence(out, quick):
    t = np.radians([p[0] for p in POINTS])
    s = np.array([p[1] for p in POINTS])
    nodes = (4, 6, 8, 10, 12, 16, 24) if quick else (4, 6, 8, 10, 12, 16, 24, 32)
    rows = []
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    worst_default = {}
    for c, sh in enumerate(SHADOWING):
        ref = dhr.dhr_quadrature(t, s, sh, n_outer=64, n_inner=48)
        errs, times = [], []
        for n in nodes:
            t0 = time.perf_counter()
            val = dhr.dhr_quadrature(np.repeat(t, 20), np.repeat(s, 20), sh, n_outer=n, n_inner=max(4, int(0.6 * n)))
            dt = (time.perf_counter() - t0) / (20 * len(t))
            err = np.abs(val[::20] - ref).max()
            errs.append(max(err, 1e-17))
            times.append(dt)
            rows.append([sh, n, max(4, int(0.6 * n)), err, dt])
        worst_default[sh] = float(np.abs(dhr.dhr_specular_pec(t, s, sh) - ref).max())
        ax1.semilogy(nodes, errs, "o-", color=f"C{c}", label=sh)
        ax2.loglog(np.array(times) * 1e3, errs, "o-", color=f"C{c}", label=sh)
    ax1.set_xlabel("Gauss-Legendre nodes per piece (outer)")
    ax1.set_ylabel("max |error| over hard points")
    ax1.axhline(1e-4, color="k", ls=":", lw=0.8)
    ax1.axvline(16, color="0.5", ls="--", lw=0.8)
    ax1.text(16.3, 1e-2, "default", fontsize=8)
    ax2.set_xlabel("time per (θi, s) pair (ms)")
    ax2.axhline(1e-4, color="k", ls=":", lw=0.8)
    for ax in (ax1, ax2):
        ax.legend(fontsize=8)
    fig.suptitle("DHR quadrature: accuracy against nodes and time")
    # the margins tight_layout chose for these labels, fixed: it measured every tick label again (~0.3 CPU s)
    fig.subplots_adjust(left=0.078, right=0.965, bottom=0.152, top=0.868, wspace=0.159)  # right: time ticks vary
    save_figure(fig, out / "dhr_convergence.png")
    write_csv(out / "dhr_convergence.csv", ["shadowing", "n_outer", "n_inner", "max_abs_error", "seconds_per_point"], rows)
    return [dict(name=f"DHR quadrature ({sh}) default rule, hard points: max error", value=v,
                 tolerance=1e-4, passed=v < 1e-4) for sh, v in worst_default.items()]


def table_error(out, quick):
    """Interpolation error of the shipped table over its whole range, rms_slope 1e-4 .. 100 and
    theta_i 0 .. 90 deg, on a grid uniform in the table's x = 1 - sqrt(cos theta_i) (so that
    the grazing layer, where near-mirror surfaces lose light to shadowing, is sampled densely)."""
    table = dhr.load_table("vgroove")
    if quick:    # coarse where rho is smooth, dense in the grazing layer (theta_i > 89.2 deg)
        x = np.concatenate([np.linspace(0.0, 0.9, 46)[:-1], np.linspace(0.9, 1.0, 101)])
        ns = 41
    else:
        x, ns = np.linspace(0.0, 1.0, 2049), 241
    nx = x.size
    ls = np.linspace(math.log(dhr.TABLE_SLOPE_RANGE[0]), math.log(dhr.TABLE_SLOPE_RANGE[1]), ns)
    X, L = np.meshgrid(x, ls, indexing="ij")
    T, S = dhr.theta_of_x(X), np.exp(L)
    t0 = time.perf_counter()
    exact = dhr.dhr_quadrature(T, S)
    seconds = time.perf_counter() - t0
    err = np.abs(table(T, S) - exact)
    grazing = np.maximum(90.0 - np.degrees(dhr.theta_of_x(x)), 1e-4)   # 90 deg - theta_i
    fig, ax = plt.subplots(figsize=(7, 4.8))
    im = ax.pcolormesh(np.exp(ls), grazing, np.log10(np.maximum(err, 1e-12)), shading="auto", cmap="viridis",
                       vmin=-10, vmax=-3)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("rms_slope")
    ax.set_ylabel("90° − θi (deg)")
    ax.axvline(50.0, color="w", ls="--", lw=0.8)
    ax.text(52, 30, "plugin\nlimit 50", color="w", fontsize=7)
    fig.colorbar(im, label="log10 |table − quadrature|")
    ax.set_title(f"DHR table (V-groove) interpolation error: max {err.max():.2g} (target 2e-4)\n"
                 f"grid {dhr.TABLE_THETA_POINTS} x {dhr.TABLE_SLOPE_POINTS}, x step 1/128, 1/512 above x = 15/16",
                 fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "dhr_table_error.png")
    write_csv(out / "dhr_table_error.csv", ["x", "theta_i_deg", "rms_slope", "rho", "abs_error"],
              [[x[i], math.degrees(T[i, 0]), math.exp(ls[j]), exact[i, j], err[i, j]]
               for i in range(nx) for j in range(ns)])
    # per decade of rms_slope, for citing
    decades = []
    for lo in range(-4, 2):
        sel = (S[0] >= 10.0 ** lo * (1 - 1e-9)) & (S[0] <= 10.0 ** (lo + 1) * (1 + 1e-9))
        e = err[:, sel]
        i, j = np.unravel_index(np.argmax(e), e.shape)
        decades.append([10.0 ** lo, 10.0 ** (lo + 1), float(e.max()), math.degrees(T[i, 0]),
                        float(S[0, sel][j])])
    write_csv(out / "dhr_table_error_by_decade.csv",
              ["rms_slope_from", "rms_slope_to", "max_abs_error", "at_theta_i_deg", "at_rms_slope"], decades)
    for row in decades:
        print(f"  rms_slope {row[0]:g}..{row[1]:g}: max table error {row[2]:.2g} "
              f"(theta_i {row[3]:.4f} deg, rms_slope {row[4]:.3g})")
    plugin = S <= 50.0
    mirror = (S[0] <= 1.0001e-4)
    mirror_flat = float(np.abs(table(np.radians(np.linspace(0, 89, 90)), 1e-4) - 1.0).max())
    return [dict(name="DHR table interpolation error, rms_slope 1e-4-100, θi 0-90° (whole table)",
                 value=float(err.max()), tolerance=2e-4, passed=bool(err.max() <= 2e-4)),
            dict(name="DHR table interpolation error, rms_slope 1e-4-50 (the plugin's range)",
                 value=float(err[plugin].max()), tolerance=2e-4, passed=bool(err[plugin].max() <= 2e-4)),
            dict(name="DHR table, near mirror (rms_slope 1e-4): max error at grazing incidence",
                 value=float(err[:, mirror].max()), tolerance=2e-4, passed=bool(err[:, mirror].max() <= 2e-4)),
            dict(name="DHR table, near mirror (rms_slope 1e-4): |rho - 1| for θi <= 89°",
                 value=mirror_flat, tolerance=1e-6, passed=bool(mirror_flat <= 1e-6)),
            dict(name=f"DHR reference quadrature time for {nx * ns} points (s)", value=seconds,
                 tolerance=float("inf"), passed=True),
            build_check()]


def build_check():
    """A fresh build of the V-groove table, timed now (what tools/make_dhr_tables.py pays per
    shadowing; the package ships the result); the load average goes into the check's name."""
    import os
    t0 = time.perf_counter()
    dhr.build_table("vgroove", progress=False)
    seconds = time.perf_counter() - t0
    return dict(name=f"DHR table build time, {dhr.TABLE_THETA_POINTS} x {dhr.TABLE_SLOPE_POINTS} (s; "
                     f"load average {os.getloadavg()[0]:.1f})", value=seconds,
                # a time is not a pass/fail check on a shared machine (10 s at load 7, 3.5 s quiet):
                # reported here, compared in benchmarks
                tolerance="reported (about 3.5 s on a quiet machine)", passed=True)


def table_resolution(out, quick):
    """Speed against accuracy for the table: grids (uniform in x, and the default with its refined
    grazing end) against build time and worst interpolation error over the whole slope range."""
    from scipy.interpolate import RectBivariateSpline
    rng = np.random.default_rng(3)
    n = 300 if quick else 1500
    # half anywhere, half in the grazing layer x > 0.9 (theta_i > 89.2 deg), all slopes 1e-4..100
    xs = np.concatenate([rng.uniform(0, 1, n), rng.uniform(0.9, 1.0, n)])
    s = np.exp(rng.uniform(math.log(1e-4), math.log(100), 2 * n))
    t = dhr.theta_of_x(xs)
    exact = dhr.dhr_quadrature(t, s)
    rows = []
    grids = [("uniform", 65, 61), ("uniform", 129, 121), ("default", 0, 121)]
    if not quick:   # quick mode (a chart, no check): the default against two coarser uniform grids
        grids = [("uniform", 33, 31)] + grids[:2] + [("uniform", 257, 121)] + grids[2:] + [("uniform", 513, 241)]
    for kind, nx, ns in grids:
        x = dhr.table_x_nodes() if kind == "default" else np.linspace(0, 1, nx)
        ls = np.linspace(math.log(1e-4), math.log(100), ns)
        X, L = np.meshgrid(x, ls, indexing="ij")
        t0 = time.perf_counter()
        rho = dhr.dhr_quadrature(dhr.theta_of_x(X), np.exp(L), n_outer=10, n_inner=6)
        build = time.perf_counter() - t0
        spl = RectBivariateSpline(x, ls, rho, kx=3, ky=3)
        err = float(np.abs(np.clip(spl.ev(dhr.x_of_theta(t), np.log(s)), 0, None) - exact).max())
        rows.append([kind, x.size, ns, build, err])
    write_csv(out / "dhr_table_resolution.csv",
              ["grid", "n_x", "n_log_slope", "build_seconds", "max_interp_error_1e-4_100"], rows)
    fig, ax = plt.subplots(figsize=(6, 4))
    uni = [r for r in rows if r[0] == "uniform"]
    ax.loglog([r[3] for r in uni], [r[4] for r in uni], "o-", label="uniform in x")
    for kind, nx, ns, sec, err in rows:
        default = kind == "default"
        ax.annotate(f"{nx}x{ns}" + (" (default)" if default else ""), (sec, err), textcoords="offset points",
                    xytext=(5, 4), fontsize=8, color="k" if default else "0.4")
        if default:
            ax.plot(sec, err, "k*", ms=14, label="default: x step 1/512 above 15/16")
    ax.axhline(2e-4, color="k", ls=":", lw=0.8)
    ax.text(rows[0][3], 2.4e-4, "target 2e-4", fontsize=7)
    ax.set_xlabel("table build time (s, 2 cores)")
    ax.set_ylabel("max interpolation error, rms_slope 1e-4-100")
    ax.set_title("DHR table: resolution, speed against accuracy\n"
                 "the near-mirror grazing layer (rms_slope ~1e-4) sets the x resolution", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out / "dhr_table_resolution.png")
    return rows


def validate(outdir="out/validation", quick=False):
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    checks = convergence(out, quick) + table_error(out, quick)
    table_resolution(out, quick)
    return checks


if __name__ == "__main__":
    cli(validate, __doc__)
