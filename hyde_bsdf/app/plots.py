"""The plots of the commands (matplotlib): a fit against its data, an inversion's history.

:func:`plot_fit` (``hyde-bsdf fit DATA.csv -o``), :func:`plot_pbsdf_fit` (``hyde-bsdf fit
FILE.pbsdf -o``), :func:`plot_selection` (misfit against model size, ``-o`` with ``--model auto``),
:func:`plot_history` (``hyde-bsdf invert``).  Every plot is written atomically
(:mod:`hyde_bsdf.io.atomic`) in a format its extension names (:data:`PLOT_FORMATS`).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hyde_bsdf.errors import UsageError
from hyde_bsdf.fit.model_selection import ModelSelection
from hyde_bsdf.fit.mueller_fit import FitResult, mueller_elements
from hyde_bsdf.fit.pbsdf_fit import PbsdfFitResult
from hyde_bsdf.fit.pbsdf_samples import PbsdfSamples
from hyde_bsdf.inverse.scalar import PARAMETERS
from hyde_bsdf.io.atomic import atomic_path
from hyde_bsdf.io.output_gate import check_output_path
from hyde_bsdf.io.measurements import Measurements

__all__ = ["PLOT_FORMATS", "PLOT_POINTS", "check_plot_path", "plot_fit", "plot_pbsdf_fit",
           "plot_history", "plot_selection", "plot_lab_fit", "plot_lab_selection"]


#: at most this many geometries are plotted (a random subset of larger data sets)
PLOT_POINTS = 2000


#: plot formats matplotlib writes without extra packages
PLOT_FORMATS = ("png", "pdf", "svg", "eps", "ps", "jpg", "jpeg", "tif", "tiff", "webp")


def plot_format(path) -> str:
    ext = Path(path).suffix.lower().lstrip(".")
    if ext not in PLOT_FORMATS:
        raise UsageError(f"plot file {str(path)!r}: the extension must be one of "
                         f"{', '.join('.' + e for e in PLOT_FORMATS)}")
    return ext


def check_plot_path(path, what: str = "plot file (-o)") -> Path:
    """The plot's path checked before any work: writable, a format :data:`PLOT_FORMATS` names."""
    path = check_output_path(path, what)
    plot_format(path)
    return path


def _save(fig, path, dpi) -> Path:
    """Write a figure atomically in the format its extension names, and close it."""
    import matplotlib.pyplot as plt

    path = check_output_path(path, "plot file")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=plot_format(path))
    plt.close(fig)
    return path


def _signed_theta_r(theta_r, phi):
    """Signed observation angle in the plane of incidence: + forward (phi = pi), - backscatter."""
    return np.where(np.cos(phi) < 0, theta_r, -theta_r)


def _subsample(meas: Measurements):
    """At most :data:`PLOT_POINTS` geometries (fixed seed) and a note saying so: a plot of 10^6
    error bars takes minutes and shows nothing."""
    if len(meas) <= PLOT_POINTS:
        return meas, ""
    keep = np.sort(np.random.default_rng(0).choice(len(meas), PLOT_POINTS, replace=False))
    return (Measurements(meas.theta_i[keep], meas.theta_r[keep], meas.phi[keep],
                         {e: v[keep] for e, v in meas.values.items()},
                         None if meas.sigma is None else {e: v[keep] for e, v in meas.sigma.items()},
                         None if meas.n_samples is None else meas.n_samples[keep], meas.source),
            f" ({PLOT_POINTS} of {len(meas)} geometries shown)")


def _specular_panel(a, name, meas, result, truth, err):
    """Specular-plane data with theta_i = theta_r (the paper's Figs. 8-9) against that angle."""
    x = np.degrees(meas.theta_i)
    dense = np.radians(np.linspace(max(0.5, x.min() - 3), min(89.0, x.max() + 3), 200))
    a.plot(np.degrees(dense), result.model(dense, dense, np.pi, (name,))[name], "C0-", label="fit")
    if truth:
        a.plot(np.degrees(dense), mueller_elements(dense, dense, np.pi, (name,), **truth, shadowing=result.shadowing,
                                                   diffuse=result.diffuse)[name], "k--", lw=0.8, label="truth")
    a.errorbar(x, meas.values[name], yerr=err, fmt="o", ms=4, color="C1", capsize=2, label="data")
    a.set_xlabel(r"$\theta_i = \theta_r$ (deg), $\phi = 180°$")


def _in_plane_panel(a, name, meas, result, err):
    """In-plane data (phi = 0 or pi) against the signed theta_r, one line per theta_i."""
    ti = meas.theta_i
    xs = np.degrees(_signed_theta_r(meas.theta_r, meas.phi))
    for c, t in enumerate(np.unique(np.round(ti, 9))):
        sel = np.isclose(ti, t)
        dense = np.radians(np.linspace(-89, 89, 300))
        mod = result.model(t, np.abs(dense), np.where(dense >= 0, np.pi, 0.0), (name,))[name]
        a.plot(np.degrees(dense), mod, f"C{c % 10}-", lw=1)
        a.errorbar(xs[sel], meas.values[name][sel], yerr=None if err is None else err[sel],
                   fmt="o", ms=3, color=f"C{c % 10}", capsize=2, label=rf"$\theta_i$={np.degrees(t):.0f}°")
    a.set_xlabel(r"signed $\theta_r$ (deg; + forward)")


def _pointwise_panel(a, name, meas, result, err):
    """Any other geometry: point by point."""
    idx = np.arange(len(meas))
    a.plot(idx, result.model(meas.theta_i, meas.theta_r, meas.phi, (name,))[name], "C0s", mfc="none", label="fit")
    a.errorbar(idx, meas.values[name], yerr=err, fmt="o", ms=3, color="C1", label="data")
    a.set_xlabel("measurement index")


def plot_fit(result: FitResult, meas: Measurements, path, title: str = "", truth: dict | None = None):
    """Plot data (means with +-1 sigma bars) against the fitted model, one panel per element.

    Specular-plane data with theta_i = theta_r (the paper's Figs. 8-9) are plotted
    against that angle with the model as a line; in-plane data (phi = 0 or pi) against
    the signed theta_r with one line per theta_i; anything else point by point.
    ``truth`` (n, k, rms_slope) adds the generating model as a dashed line.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    meas, note = _subsample(meas)
    names = meas.elements
    ncol = min(len(names), 4)
    nrow = math.ceil(len(names) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.6 * ncol, 3.2 * nrow), squeeze=False)
    ph = meas.phi
    in_plane = np.all(np.isclose(np.cos(ph) ** 2, 1.0))
    specular = in_plane and np.all(np.isclose(meas.theta_i, meas.theta_r)) and np.all(np.cos(ph) < 0)
    for a, name in zip(axes.ravel(), names):
        err = None if meas.sigma is None else meas.sigma[name]
        if specular:
            _specular_panel(a, name, meas, result, truth, err)
        elif in_plane:
            _in_plane_panel(a, name, meas, result, err)
        else:
            _pointwise_panel(a, name, meas, result, err)
        a.set_title(f"{name}/M00")
        a.grid(alpha=0.3)
    for a in axes.ravel()[len(names):]:
        a.axis("off")
    axes.ravel()[0].legend(fontsize=7)
    pr = result.params
    fig.suptitle((title + note + "\n" if title or note else "") +
                 rf"fit: $\eta$ = {pr['n']:.4g} - j{pr['k']:.4g}, rms_slope = {pr['rms_slope']:.4g}; "
                 rf"$\chi^2_\nu$ = {result.reduced_chi2:.3g}", fontsize=9)
    fig.tight_layout()
    return _save(fig, path, 120)


def plot_pbsdf_fit(result: PbsdfFitResult, data: PbsdfSamples, path, title: str = "", max_points: int = 1500):
    """Fit against data per Mueller element: 16 panels of model (y) against table (x) at the fitted
    geometries, every band in its own colour; M00 in 1/sr on log axes, the others normalized by M00."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = np.arange(len(data))
    if rows.size > max_points:
        rows = np.sort(np.random.default_rng(0).choice(rows, max_points, replace=False))
    fig, axes = plt.subplots(4, 4, figsize=(12, 11))
    cmap = plt.get_cmap("viridis")
    K = data.wavelengths.size
    model = np.stack([result.model(data.theta_i[rows], data.theta_r[rows], data.phi[rows], b) for b in range(K)])
    table = data.F[:, rows]
    colours = np.repeat([cmap(b / max(K - 1, 1)) for b in range(K)], rows.size, axis=0)
    for j in range(4):
        for k in range(4):
            a = axes[j, k]
            if (j, k) == (0, 0):       # one scatter per panel (every band at once): drawing is the cost
                a.scatter(table[..., 0, 0].ravel(), model[..., 0, 0].ravel(), s=2, c=colours, lw=0)
                a.set_xscale("log")
                a.set_yscale("log")
            else:
                a.scatter((table[..., j, k] / table[..., 0, 0]).ravel(), (model[..., j, k] / model[..., 0, 0]).ravel(),
                          s=2, c=colours, lw=0)
    for b in range(K):
        axes[0, 0].plot([], [], ".", color=cmap(b / max(K - 1, 1)), label=f"{data.wavelengths[b]:g} nm")
    for j in range(4):
        for k in range(4):
            a = axes[j, k]
            lo, hi = a.get_xlim()
            lo, hi = min(lo, a.get_ylim()[0]), max(hi, a.get_ylim()[1])
            a.plot([lo, hi], [lo, hi], "k-", lw=0.6)
            a.set_title("M00 (1/sr)" if (j, k) == (0, 0) else f"M{j}{k}/M00", fontsize=9)
            a.tick_params(labelsize=7)
            if j == 3:
                a.set_xlabel("table", fontsize=8)
            if k == 0:
                a.set_ylabel("fitted model", fontsize=8)
    axes[0, 0].legend(fontsize=6, markerscale=2)
    fig.suptitle((title + "\n" if title else "") +
                 f"rms_slope = {result.rms_slope:.4g}; n = {', '.join(f'{v:.3g}' for v in result.n)}; "
                 f"k = {', '.join(f'{v:.3g}' for v in result.k)} ({len(rows)} of {len(data)} geometries)", fontsize=9)
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.05, top=0.92, wspace=0.3, hspace=0.35)
    return _save(fig, path, 90)


def plot_history(results: dict, path, title: str = "") -> Path:
    """Loss and parameter trajectories (relative to the truth when known) of one or more runs."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 1 + len(PARAMETERS), figsize=(4.2 * (1 + len(PARAMETERS)), 3.4))
    for c, (label, res) in enumerate(results.items()):
        it = [r["iteration"] for r in res.history]
        axes[0].semilogy(it, [r["loss"] for r in res.history], f"C{c}-", lw=1, label=label)
        for a, p in zip(axes[1:], PARAMETERS):
            a.plot(it, [r[p] for r in res.history], f"C{c}-", lw=1.2, label=label)
            if res.truth:
                a.axhline(res.truth[p], color="k", ls="--", lw=0.8)
    axes[0].set_title("loss (each run's own)")
    axes[0].set_xlabel("iteration")
    axes[0].legend(fontsize=7)
    for a, p in zip(axes[1:], PARAMETERS):
        a.set_title(f"{p} (dashed: truth)")
        a.set_xlabel("iteration")
        a.grid(alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return path


def plot_selection(sel: ModelSelection, path, title: str = ""):
    """Misfit against model size, one point per candidate (the chosen one ringed), as PNG/PDF/SVG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    live = [r for r in sel.rows if r.stage != "undefined"]
    key = "reduced_chi2" if "reduced_chi2" in live[0].misfit else ("M00" if "M00" in live[0].misfit else "elements")
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in live:
        y = r.misfit[key] * (100 if key == "M00" else 1)
        ax.semilogy(r.size + (0.15 if r.dielectric else 0), y, "o", color="C2" if r.adequate else "C3", ms=7)
        ax.annotate(r.label, (r.size + (0.15 if r.dielectric else 0), y), fontsize=7, xytext=(4, 2),
                    textcoords="offset points")
    c = sel.choice
    ax.semilogy(c.size + (0.15 if c.dielectric else 0), c.misfit[key] * (100 if key == "M00" else 1), "o",
                mfc="none", mec="k", ms=14, label=f"chosen: {c.label}")
    ax.set_xlabel("model size (free parameters + terms)")
    ax.set_ylabel({"reduced_chi2": "reduced chi^2", "M00": "M00 rms misfit (%)",
                   "elements": "normalized-element rms misfit"}[key])
    ax.set_title((title + "\n" if title else "") + "green: adequate, red: inadequate", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path, 110)


def plot_lab_fit(result, path, title: str = ""):
    """Measured values (+-1 sigma) against the fitted model, one panel per value column (M00 in 1/sr,
    the normalized elements), one colour per wavelength: points on the diagonal fit."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f = result.fit
    d = f.data
    model = f.prediction()
    cols = d.columns
    ncol = min(len(cols), 4)
    nrow = math.ceil(len(cols) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.4 * ncol, 3.1 * nrow), squeeze=False)
    for a, name in zip(axes.ravel(), cols):
        for g, group in enumerate(d.groups):
            y, m = d.column(d.y, name, g), d.column(model, name, g)
            err = None if d.w is None else d.column(d.w, name, g)
            a.errorbar(m, y, yerr=err, fmt=".", ms=3, lw=0.6, alpha=0.7, label=group.label)
        lo = min(a.get_xlim()[0], a.get_ylim()[0])
        hi = max(a.get_xlim()[1], a.get_ylim()[1])
        a.plot([lo, hi], [lo, hi], "k-", lw=0.7)
        a.set_title(name + (" (1/sr)" if name == "M00" or d.absolute else "/M00"), fontsize=9)
        a.set_xlabel("model", fontsize=8)
        a.set_ylabel("measured", fontsize=8)
        a.grid(alpha=0.3)
    for a in axes.ravel()[len(cols):]:
        a.axis("off")
    axes.ravel()[0].legend(fontsize=7)
    pr = f.values[("rms_slope", None)]
    fig.suptitle((title + "\n" if title else "") + f"{result.model.label}: rms_slope = {pr:.4g}; "
                 rf"$\chi^2_\nu$ = {f.reduced_chi2:.3g}; " + ("adequate" if f.verdict.adequate else "INADEQUATE"),
                 fontsize=9)
    fig.tight_layout()
    return _save(fig, path, 110)


def plot_lab_selection(result, path, title: str = ""):
    """The lab fit's candidates: reduced chi^2 against model size (the chosen one ringed)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in result.selection.rows:
        x, y = r.size + (0.15 if r.model.dielectric else 0), r.fit.reduced_chi2
        ax.semilogy(x, y, "o", color="C2" if r.adequate else "C3", ms=7)
        ax.annotate(r.model.label, (x, y), fontsize=7, xytext=(4, 2), textcoords="offset points")
        if r.chosen:
            ax.semilogy(x, y, "o", mfc="none", mec="k", ms=14, label=f"chosen: {r.model.label}")
    ax.set_xlabel("model size (free parameters + terms)")
    ax.set_ylabel("reduced chi^2")
    ax.set_title((title + "\n" if title else "") + "green: adequate, red: inadequate", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path, 110)
