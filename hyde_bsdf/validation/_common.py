"""Shared pieces of the validation scripts: the command line, the report's protocol, the
stability-map chart, and MoM curves with the angles the result flags (below the truncated
partition's floor) drawn grey with the reason.

**The report's protocol.**  ``hyde-bsdf validate`` never imports a script: it runs each one as a
child process, ``python hyde_bsdf/validation/STEM.py -o OUTDIR [--quick] --checks-json FILE``, and reads
``FILE`` back.  Every script's ``__main__`` block goes through :func:`cli`, which handles that
option here, once: it runs ``validate(OUTDIR, quick)`` and writes (atomically)
``{"doc": <the script's docstring>, "checks": [dict(name, value, tolerance, passed[, detail]), ...],
"figures": [<the PNG files saved by save_figure>], "cpu_seconds": <its CPU time>}``
as JSON (NumPy scalars as Python numbers, anything else unknown as its ``str``), then exits 0.
The report shows the figures a script names (several scripts may write into the folder at once),
so every figure goes through :func:`save_figure`.
No ``FILE`` after the child ends means the script crashed: the report shows the last lines of its
stderr as a failed check.  A script with its own command line passes it as ``cli(validate,
__doc__, main)``: without ``--checks-json`` its ``main()`` runs as before.  With several scripts at once
the report sets ``HYDE_DRJIT_THREADS`` (each script's share of the cores); :func:`cli` sizes Dr.Jit's
thread pool from it before ``validate`` runs (:func:`drjit_threads`).
"""
import argparse
import gc
import json
import math
import os
import sys
import textwrap
import time

import numpy as np

CLASSES = ("accurate", "degrades", "refuses", "fails")
#: the PNG files :func:`save_figure` wrote in this process, in order (the protocol's "figures")
FIGURES = []
COLOURS = {"accurate": "#2ca02c", "degrades": "#ff7f0e", "refuses": "#7f7f7f", "fails": "#d62728"}


def cli(validate, doc, main=None):
    """``python SCRIPT.py [-o OUTDIR] [--quick] [--checks-json FILE]``: run ``validate`` and print
    each check, or (``--checks-json``) answer the report's protocol (see the module docstring).
    ``main``: the script's own command line, run (its return value the exit status) when the call
    is not the report's."""
    if main is not None and "--checks-json" not in sys.argv[1:]:
        sys.exit(main())
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-o", "--outdir", default="out/validation", help="output folder (default out/validation)")
    ap.add_argument("--quick", action="store_true", help="smaller sweeps (as in the quick report)")
    ap.add_argument("--checks-json", metavar="FILE",
                    help="write the docstring and the checks as JSON to FILE (how hyde-bsdf validate reads them)")
    a = ap.parse_args()
    drjit_threads()
    # a short process of its own: it keeps freed heap blocks, as the MoM's pool workers do (the scripts that solve
    # partitions in-process allocate and free the same large temporaries; measured: stability_mom --quick spent
    # 1.7 CPU s in page faults, 0.4 with this)
    from hyde_bsdf.resources import keep_freed_memory
    keep_freed_memory()
    # what the imports made lives to the end of this short process: out of the collector's sight, so that the
    # full collections a frozen Dr.Jit loop asks for before each replay (hyde_bsdf.inverse.maps._gradient) walk
    # only the objects of the run (measured: 75 -> 0 ms per collection at start; svbrdf_index --quick makes 40)
    gc.freeze()
    checks = list(validate(a.outdir, quick=a.quick))
    if a.checks_json:
        write_checks_json(a.checks_json, doc, checks)
        sys.exit(0)
    for c in checks:
        print(("PASS" if c["passed"] else "FAIL"), c["name"], c["value"])
    sys.exit(0 if all(c["passed"] for c in checks) else 1)


def drjit_threads():
    """Size Dr.Jit's thread pool from ``HYDE_DRJIT_THREADS`` when the report sets it (its share of the cores with
    several scripts at once, ``hyde_bsdf.app.report.build.THREAD_VARIABLES``: Dr.Jit reads no variable itself)."""
    threads = os.environ.get("HYDE_DRJIT_THREADS", "")
    if threads.isdigit() and int(threads) > 0:
        import drjit

        drjit.set_thread_count(int(threads))


def _plain(value):
    """A JSON-able form of a check's field: NumPy scalars as Python numbers, else ``str``."""
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    if hasattr(value, "item") and np.ndim(value) == 0:
        return value.item()
    return str(value)


def cpu_seconds():
    """This process's CPU time so far (user + system, every thread), with that of the processes it
    started and waited for (the MoM's worker pool)."""
    try:
        import resource
    except ImportError:             # not on POSIX: this process only
        return time.process_time()
    return sum(r.ru_utime + r.ru_stime for r in (resource.getrusage(resource.RUSAGE_SELF),
                                                  resource.getrusage(resource.RUSAGE_CHILDREN)))


def write_checks_json(path, doc, checks):
    """The report's protocol: ``{"doc": ..., "checks": [...], "figures": [...], "cpu_seconds": ...}``
    written atomically to ``path``."""
    from hyde_bsdf.io.atomic import atomic_open

    data = {"doc": (doc or "").strip(),
            "checks": [{k: _plain(v) for k, v in dict(c).items()} for c in checks],
            "figures": list(FIGURES), "cpu_seconds": cpu_seconds()}
    with atomic_open(path, "w", encoding="utf-8") as f:
        json.dump(data, f)


def db(x):
    """10 log10(x), a zero held at -300 dB (a curve's zero, not an error)."""
    return 10.0 * np.log10(np.maximum(x, 1e-30))


def mom_parser(doc, outdir="out/validation/"):
    """The MoM scripts' shared options: ``-o OUTDIR``, ``--pts-per-wl``, ``--seed``."""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("-o", "--outdir", default=outdir)
    ap.add_argument("--pts-per-wl", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=0)
    return ap


def write_csv(path, header, rows):
    """Write the numbers behind a figure: one header row, then ``rows`` (atomically: a temporary
    file beside ``path``, renamed over it once complete)."""
    import csv

    from hyde_bsdf.io.atomic import atomic_open
    with atomic_open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


def save_figure(fig, path, dpi=130, tight=False):
    """Save a matplotlib figure as PNG (atomically), close it, and name it in the report's
    protocol (:data:`FIGURES`); ``tight``: lay it out tightly first."""
    import matplotlib.pyplot as plt

    if tight:
        fig.tight_layout()

    from hyde_bsdf.io.atomic import atomic_path
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        plt.close(fig)
    FIGURES.append(str(path))


def sweep_chart(sweeps, path, title, **kw):
    """Run each stability sweep ``(title, values, fn)`` (``fn(value)`` -> (class, error, message)), draw
    them with :func:`stability_chart` and return the CSV rows [title, value, class, error, message]."""
    rows, panels = [], []
    for name, values, fn in sweeps:
        res = [fn(v) for v in values]
        panels.append((name, values, res))
        rows += [[name, v, c, e, msg] for v, (c, e, msg) in zip(values, res)]
    stability_chart(panels, path, title, **kw)
    return rows


def stability_chart(panels, path, title, err_label="rel. err", err_ylim=(1e-17, 1.0), text_errors=False):
    """One bar row per sweep, coloured by class; errors as dots (log axis) or as text.

    ``panels``: list of (title, values, [(class, error, message), ...]).
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 1.3 * len(panels) + 0.8))
    for ax, (sub, values, res) in zip(np.atleast_1d(axes), panels):
        x = np.arange(len(values))
        ax.bar(x, 1, width=1.0, color=[COLOURS[c] for c, _, _ in res])
        errs = np.array([e for _, e, _ in res], dtype=float)
        if text_errors:
            for j, e in enumerate(errs):
                if math.isfinite(e):
                    ax.text(j, 0.5, f"{e:.3f}", ha="center", fontsize=6, rotation=90)
            ax.set_xticks(x, [f"{v:g}" for v in values], fontsize=7)
        else:
            ax2 = ax.twinx()
            ax2.semilogy(x, np.where(np.isfinite(errs) & (errs > 0), errs, np.nan), "k.", ms=3)
            ax2.set_ylim(*err_ylim)
            ax2.set_ylabel(err_label, fontsize=7)
            ticks = np.linspace(0, len(values) - 1, 6).astype(int)
            ax.set_xticks(ticks, [f"{values[t]:.3g}" for t in ticks], fontsize=7)
        ax.set_yticks([])
        ax.set_title(sub, fontsize=8)
    handles = [plt.Rectangle((0, 0), 1, 1, color=COLOURS[c]) for c in CLASSES]
    fig.legend(handles, CLASSES, loc="lower center", ncol=4, fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    save_figure(fig, path, dpi=120)


#: the colour and marker of a MoM value the result flags (``MoMResult.valid_s`` / ``valid_p`` False)
FLAGGED_STYLE = dict(color="0.55", marker="x", ms=2.5, alpha=0.8)


#: the start of every flagged curve's legend entry
FLAGGED_PREFIX = "grey x: flagged"


def flagged_label(reason, width=80):
    """The legend entry of flagged angles: "grey x: flagged -- REASON" wrapped to ``width`` characters."""
    return textwrap.fill(FLAGGED_PREFIX + ", not the surface's -- " + reason, width)


def plot_flagged(ax, x, y, valid, reason=None, **kw):
    """Plot a MoM curve y(x) (keyword arguments as for ``ax.plot``) where the result is reported valid; at the
    angles it flags (``valid`` False: below the truncated partition's floor, ``MoMResult.floor_reason``) the curve
    is broken and its values drawn grey with crosses.  With ``reason`` and at least one flagged angle, the grey
    curve carries the legend entry :func:`flagged_label` -- once per axes.  Returns (valid line, flagged line)."""
    y = np.asarray(y, float)
    valid = np.broadcast_to(np.asarray(valid, bool), y.shape)
    good, = ax.plot(x, np.where(valid, y, np.nan), **kw)
    style = {k: v for k, v in kw.items() if k in ("ls", "linestyle", "lw", "linewidth", "zorder")}
    label = flagged_label(reason) if reason and not valid.all() else None
    if label in ax.get_legend_handles_labels()[1]:
        label = None
    bad, = ax.plot(x, np.where(valid, np.nan, y), label=label, **FLAGGED_STYLE, **style)
    return good, bad


def legend_entries(axes, flagged):
    """(handles, labels) of the flagged curves (:func:`plot_flagged`) or of the others, over ``axes``, each once."""
    out = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            if label.startswith(FLAGGED_PREFIX) == flagged:
                out.setdefault(label, handle)
    return list(out.values()), list(out)


def flagged_legend(target, **kw):
    """A legend of the flagged entries only, where there are any: on an axes (for the panels whose other curves the
    figure's first legend names), or on a figure (below its panels, gathered from all of them)."""
    axes = getattr(target, "axes", None)
    handles, labels = legend_entries(axes if isinstance(axes, list) else [target], True)
    if handles:
        target.legend(handles, labels, **kw)
    return bool(handles)


def valid_m00(res):
    """Where the MoM's M00 = (sigma_s + sigma_p) / 2 stands clear of its floor: M00 >= FLOOR_MARGIN x the mean of the
    two polarisations' floors (the floors add; the same margin as ``valid_s`` / ``valid_p``); the scripts flag the
    ratios M01/M00, M22/M00, M23/M00 at the same angles."""
    from hyde_bsdf.mom.floor import FLOOR_MARGIN

    return res.mueller["M00"] >= FLOOR_MARGIN * 0.5 * (res.floor_s + res.floor_p)


def atlas_checks(title, theta_i_deg, rms_slope, sigma_h_wl, cases):
    """The accuracy atlas's verdict (hyde_bsdf.model.accuracy.verdict) for a script's geometry, one reported check
    per material: ``cases`` [(label, n, k)] (n None: a PEC), the model V-groove with the paper's diffuse term."""
    from hyde_bsdf.model.accuracy import verdict

    out = []
    for label, n, k in cases:
        v = verdict(np.radians(theta_i_deg), rms_slope, n, k, sigma_h_wl=sigma_h_wl)
        out.append(dict(name=f"{title}, {label}: the accuracy atlas's verdict for this geometry (rms slope "
                             f"{rms_slope:g}, sigma_h {sigma_h_wl:.3g} lambda)", value=v["summary"],
                        tolerance="reported", passed=True))
    return out
