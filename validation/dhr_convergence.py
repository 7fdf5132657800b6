"""Convergence of the specular DHR (paper Eqs. 14-16) and accuracy of its cached table.

1. Quadrature error against Gauss-Legendre nodes per piece, and against run time, for the
   three shadowing models at hard points (narrow lobes, grazing incidence).
2. Table interpolation error over (theta_i, rms_slope) (bicubic in (x, ln s),
   x = 1 - sqrt(cos theta)) against direct quadrature, as a map.
3. Table resolution (nodes per axis) against build time and worst interpolation error.

Writes dhr_convergence.png/.csv, dhr_table_error.png/.csv, dhr_table_resolution.png/.csv into OUTDIR.
"""
import sys
import math
import time
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cli, save_figure, write_csv  # noqa: E402

from hyde_bsdf.model import dhr

POINTS = [(0.0, 0.01), (45.0, 0.3), (80.0, 0.05), (89.0, 0.5), (89.9, 0.01), (60.0, 3.0)]


def convergence(out, quick):
    t = np.radians([p[0] for p in POINTS])
    s = np.array([p[1] for p in POINTS])
    nodes = (4, 6, 8, 10, 12, 16, 24) if quick else (4, 6, 8, 10, 12, 16, 24, 32)
    rows = []
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    worst_default = {}
    for c, sh in enumerate(dhr.SHADOWING):
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
    fig.tight_layout()
    save_figure(fig, out / "dhr_convergence.png")
    write_csv(out / "dhr_convergence.csv", ["shadowing", "n_outer", "n_inner", "max_abs_error", "seconds_per_point"], rows)
    return [dict(name=f"DHR quadrature ({sh}) default rule, hard points: max error", value=v,
                 tolerance=1e-4, passed=v < 1e-4) for sh, v in worst_default.items()]


def table_error(out, quick):
    table = dhr.load_table("vgroove")
    nt, ns = (60, 40) if quick else (150, 100)
    deg = np.linspace(0, 89.9, nt)
    ls = np.linspace(math.log(1e-3), math.log(5), ns)
    T, L = np.meshgrid(np.radians(deg), ls, indexing="ij")
    err = np.abs(table(T, np.exp(L)) - dhr.dhr_quadrature(T, np.exp(L)))
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    im = ax.pcolormesh(np.exp(ls), deg, np.log10(np.maximum(err, 1e-12)), shading="auto", cmap="viridis",
                       vmin=-10, vmax=-3)
    ax.set_xscale("log")
    ax.set_xlabel("rms_slope")
    ax.set_ylabel("θi (deg)")
    fig.colorbar(im, label="log10 |table - quadrature|")
    ax.set_title("DHR table (V-groove) interpolation error")
    fig.tight_layout()
    save_figure(fig, out / "dhr_table_error.png")
    write_csv(out / "dhr_table_error.csv", ["theta_i_deg", "rms_slope", "abs_error"],
              [[deg[i], math.exp(ls[j]), err[i, j]] for i in range(nt) for j in range(ns)])
    S = np.exp(L)
    in_spec = (S >= 0.01) & (S <= 3)
    return [dict(name="DHR table interpolation error, rms_slope 0.01-3, θi 0-89.9°", value=float(err[in_spec].max()),
                 tolerance=2e-4, passed=bool(err[in_spec].max() <= 2e-4)),
            dict(name="DHR table interpolation error, rms_slope 1e-3-5, θi 0-89.9°", value=float(err.max()),
                 tolerance=2e-4, passed=bool(err.max() <= 2e-4)),
            dict(name="DHR table build time (s)", value=float(table.build_seconds), tolerance=5.0,
                 passed=bool(table.build_seconds <= 5.0 or not math.isfinite(table.build_seconds)))]


def table_resolution(out, quick):
    """Speed against accuracy for the table: nodes per axis vs build time and worst error."""
    from scipy.interpolate import RectBivariateSpline
    rng = np.random.default_rng(3)
    t = rng.uniform(0, math.radians(89.9), 300)
    s = np.exp(rng.uniform(math.log(0.01), math.log(3), 300))
    exact = dhr.dhr_quadrature(t, s)
    rows = []
    for nx, ns in ((33, 31), (65, 61), (129, 121)) if quick else ((17, 16), (33, 31), (65, 61), (129, 121), (257, 241)):
        x = np.linspace(0, 1, nx)
        ls = np.linspace(math.log(1e-4), math.log(100), ns)
        X, L = np.meshgrid(x, ls, indexing="ij")
        t0 = time.perf_counter()
        rho = dhr.dhr_quadrature(dhr.theta_of_x(X), np.exp(L), n_outer=10, n_inner=6)
        build = time.perf_counter() - t0
        spl = RectBivariateSpline(x, ls, rho, kx=3, ky=3)
        err = float(np.abs(spl.ev(dhr.x_of_theta(t), np.log(s)) - exact).max())
        rows.append([nx, ns, build, err])
    write_csv(out / "dhr_table_resolution.csv", ["n_x", "n_log_slope", "build_seconds", "max_interp_error_0.01_3"], rows)
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.loglog([r[2] for r in rows], [r[3] for r in rows], "o-")
    for nx, ns, sec, err in rows:
        default = (nx, ns) == (dhr.TABLE_THETA_POINTS, dhr.TABLE_SLOPE_POINTS)
        ax.annotate(f"{nx}x{ns}" + (" (default)" if default else ""), (sec, err), textcoords="offset points",
                    xytext=(5, 4), fontsize=8, color="k" if default else "0.4")
        if default:
            ax.plot(sec, err, "k*", ms=14)
    ax.axhline(2e-4, color="k", ls=":", lw=0.8)
    ax.text(rows[0][2], 2.4e-4, "target 2e-4", fontsize=7)
    ax.set_xlabel("table build time (s, 2 cores)")
    ax.set_ylabel("max interpolation error, rms_slope 0.01-3")
    ax.set_title("DHR table: resolution, speed against accuracy\n"
                 "default: the smallest table 10x below the target (errors fall ~h^4)", fontsize=9)
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
