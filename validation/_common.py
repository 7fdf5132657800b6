"""Shared pieces of the validation scripts: the command line, the report's protocol and the
stability-map chart.

**The report's protocol.**  ``hyde-bsdf validate`` never imports a script: it runs each one as a
child process, ``python validation/STEM.py -o OUTDIR [--quick] --checks-json FILE``, and reads
``FILE`` back.  Every script's ``__main__`` block goes through :func:`cli`, which handles that
option here, once: it runs ``validate(OUTDIR, quick)`` and writes (atomically)
``{"doc": <the script's docstring>, "checks": [dict(name, value, tolerance, passed[, detail]), ...]}``
as JSON (NumPy scalars as Python numbers, anything else unknown as its ``str``), then exits 0.
No ``FILE`` after the child ends means the script crashed: the report shows the last lines of its
stderr as a failed check.  A script with its own command line passes it as ``cli(validate,
__doc__, main)``: without ``--checks-json`` its ``main()`` runs as before.
"""
import argparse
import json
import math
import sys

import numpy as np

CLASSES = ("accurate", "degrades", "refuses", "fails")
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
    checks = list(validate(a.outdir, quick=a.quick))
    if a.checks_json:
        write_checks_json(a.checks_json, doc, checks)
        sys.exit(0)
    for c in checks:
        print(("PASS" if c["passed"] else "FAIL"), c["name"], c["value"])
    sys.exit(0 if all(c["passed"] for c in checks) else 1)


def _plain(value):
    """A JSON-able form of a check's field: NumPy scalars as Python numbers, else ``str``."""
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    if hasattr(value, "item") and np.ndim(value) == 0:
        return value.item()
    return str(value)


def write_checks_json(path, doc, checks):
    """The report's protocol: ``{"doc": ..., "checks": [...]}`` written atomically to ``path``."""
    from hyde_bsdf.io.atomic import atomic_open

    data = {"doc": (doc or "").strip(),
            "checks": [{k: _plain(v) for k, v in dict(c).items()} for c in checks]}
    with atomic_open(path, "w", encoding="utf-8") as f:
        json.dump(data, f)


def write_csv(path, header, rows):
    """Write the numbers behind a figure: one header row, then ``rows`` (atomically: a temporary
    file beside ``path``, renamed over it once complete)."""
    import csv

    from hyde_bsdf.io.atomic import atomic_open
    with atomic_open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


def save_figure(fig, path, dpi=130):
    """Save a matplotlib figure as PNG (atomically) and close it."""
    import matplotlib.pyplot as plt

    from hyde_bsdf.io.atomic import atomic_path
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        plt.close(fig)


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
