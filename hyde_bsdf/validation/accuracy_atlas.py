"""The accuracy atlas (issue 32): where each model variant holds against exact EM, and whether the atlas's own
verdicts hold on exact results it was not made from.

    python hyde_bsdf/validation/accuracy_atlas.py [-o OUTDIR] [--quick]        the checks below (as every validation script)
    python hyde_bsdf/validation/accuracy_atlas.py run   [--checkpoints DIR] [--workers N | --dask ADDRESS]
    python hyde_bsdf/validation/accuracy_atlas.py table [--checkpoints DIR] [-o hyde_bsdf/data/accuracy_atlas.npz]
    python hyde_bsdf/validation/accuracy_atlas.py heldout [--checkpoints DIR]

``run`` solves the MoM for every surface and material of the grid (hyde_bsdf/mom/atlas.py: 36 surfaces x 5
materials, both polarisations, 10 incidence angles each) on a process pool of ``--workers`` (default 2) or
on a dask cluster (``--dask tcp://host:8786``; ``pip install hyde-bsdf[distributed]``), writing one checkpoint
per surface and material into ``--checkpoints`` (default out/atlas_runs) as each finishes; run it again
after a kill and it resumes with the tasks not yet done (about 2 CPU hours; run it niced, ``nice -n 19``).
``table`` compares every model variant of the registry (hyde_bsdf.model.terms, through the 1-D reduction
hyde_bsdf.mom.model1d) with the checkpoints and writes the table with its provenance, in minutes and
without the MoM: a new variant joins the atlas by re-running ``table``.  ``heldout`` runs the MoM where
the atlas has no node (the held-out check below) into its own folder (default out/atlas_heldout).

The atlas (hyde_bsdf/data/accuracy_atlas.npz; read by ``hyde-bsdf accuracy`` and hyde_bsdf.model.accuracy)
holds, for 1-D Gaussian rough surfaces at incidence
0-85 deg, rms slope 0.05-0.7 and sigma_h / lambda 0.1-4, of a PEC, Al at 1550 and 633 nm, Au at 633 nm and
glass, the error of every model variant (shadowing x diffuse of the model's registry, the 1-D reduction
hyde_bsdf.mom.model1d) against the MoM's incoherent in-plane Mueller elements -- M00 in dB, M01/M00,
M11/M00, M22/M00, M23/M00 as differences -- over the lobe, at the specular angle and in the wing, with the
MoM's jackknife standard error beside each, and each variant's cost per evaluation.

Checks:

1. Reproduction (both modes): a grid cell is recomputed with the MoM at the shipped seeds (the table's
   numbers again, to rounding) and one with new seeds (within 2 combined standard errors, plus 1 % of the
   tolerance, for >= 90 % of the graded numbers: what "the MoM's statistical error" means).
2. Held-out (full mode): MoM runs at surfaces, incidence angles and a material the atlas does not contain
   (``heldout``: 6 surfaces off the slope and height axes, theta_i = 5, 25,
   45, 65, 75 deg, PEC, Al 633 nm and Ag 633 nm -- between the atlas's Al and Au) against the atlas's stated
   error at those points: the true error (the held-out run's) within the stated error + 2 of the run's
   standard errors in >= 90 % of the graded numbers, and every number the atlas calls valid within the
   tolerance.  The held-out runs are reused from OUTDIR/atlas_heldout when present (about 10 CPU minutes
   otherwise).

Writes accuracy_atlas_maps.png (the atlas as maps per element and material: (slope, height) x theta_i,
coloured by the verdict of the paper's variant), accuracy_atlas_speed.png (accuracy against time per
method), accuracy_atlas.csv (per cell and variant, the lobe errors and the verdicts) and, in full mode,
accuracy_atlas_maps_<element>.png (one per element, the errors written in) and accuracy_atlas_heldout.csv.
"""
import argparse
import json
import math
import sys
import textwrap
import time
from pathlib import Path

import numpy as np

from hyde_bsdf.validation._common import cli, save_figure, write_csv

#: the held-out surfaces (rms slope, sigma_h / lambda), angles and materials: off every grid axis
HELDOUT_SURFACES = ((0.15, 0.3), (0.27, 0.7), (0.42, 1.5), (0.6, 3.0), (0.08, 0.35), (0.27, 2.8))
HELDOUT_THETA_I = (5.0, 25.0, 45.0, 65.0, 75.0)
HELDOUT_MATERIALS = ("PEC", "Al_633nm", "Ag_633nm")
#: the held-out surfaces' seeds start here (the grid's at 10000): no held-out surface reuses a grid draw
HELDOUT_SEED_BASE = 90000
#: the cells recomputed: (key of the grid's task, same seeds?)
REPRODUCE = (("s0.35_h1_PEC", True), ("s0.2_h0.5_PEC", False))
ELEMENT_LABELS = {"M00_dB": "M00 (dB)", "M01": "M01/M00", "M11": "M11/M00", "M22": "M22/M00", "M23": "M23/M00"}


def _atlas():
    from hyde_bsdf.model.accuracy import load_atlas

    return load_atlas()


def _tolerances(atlas):
    from hyde_bsdf.model.accuracy import TOLERANCE, TOLERANCE_DB

    return np.array([TOLERANCE_DB if e == "M00_dB" else TOLERANCE for e in atlas.elements])


def verdict_codes(err, se, tol):
    """0 valid (err + 2 se <= tol), 1 undecided, 2 invalid (err > tol), 3 unknown (NaN) -- as model.accuracy."""
    code = np.where(err + 2 * se <= tol, 0, np.where(err > tol, 2, 1))
    return np.where(np.isfinite(err), code, 3)


def _codes_map(atlas, e, v):
    """Verdict codes [material, slope x height, theta_i] of element e, variant v, over the lobe; and the errors."""
    lobe = atlas.regions.index("lobe")
    err = atlas["error"][:, :, :, :, v, e, lobe].astype(float)
    se = atlas["se"][:, :, :, :, v, e, lobe].astype(float)
    shape = (len(atlas.materials), -1, atlas.theta_i.size)
    return verdict_codes(err, se, _tolerances(atlas)[e]).reshape(shape), err.reshape(shape)


def _draw_map(ax, atlas, codes, err=None):
    from matplotlib.colors import ListedColormap

    ax.imshow(codes, cmap=ListedColormap(VERDICT_COLOURS), vmin=-0.5, vmax=3.5, aspect="auto",
              interpolation="nearest")
    if err is not None:
        for (r, c), val in np.ndenumerate(err):
            if math.isfinite(val):
                ax.text(c, r, f"{val:.2g}", ha="center", va="center", fontsize=4.5)
    ax.set_xticks(range(atlas.theta_i.size), [f"{t:g}" for t in atlas.theta_i], fontsize=5)
    for r in range(1, atlas.slopes.size):
        ax.axhline(r * atlas.heights.size - 0.5, color="k", lw=0.6)


VERDICT_COLOURS = ["#2ca02c", "#ffdd57", "#d62728", "#bbbbbb"]
MAP_NOTE = ("green valid (error + 2 se within the tolerance: 1 dB, 0.1), yellow undecided, red invalid, grey unknown; "
            "rows: rms slope s and sigma_h/lambda h; columns theta_i (deg)")


def maps_all(atlas, path, variant=("vgroove", "paper")):
    """The atlas in one picture: elements (rows) x materials (columns), each a (slope, height) x theta_i map."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = atlas.variants.index(variant)
    n_el, n_m = len(atlas.elements), len(atlas.materials)
    fig, axes = plt.subplots(n_el, n_m, figsize=(2.2 * n_m + 1.0, 2.6 * n_el), sharex=True, sharey=True, squeeze=False)
    labels = [f"s {s:g} h {h:g}" if h == atlas.heights[0] else f"h {h:g}" for s in atlas.slopes for h in atlas.heights]
    for e, name in enumerate(atlas.elements):
        codes, _ = _codes_map(atlas, e, v)
        for m in range(n_m):
            ax = axes[e, m]
            _draw_map(ax, atlas, codes[m])
            if e == 0:
                ax.set_title(atlas.materials[m], fontsize=8)
            if m == 0:
                ax.set_ylabel(ELEMENT_LABELS[name], fontsize=8)
                ax.set_yticks(range(len(labels)), labels, fontsize=4)
    fig.suptitle(textwrap.fill(f"Accuracy atlas: model {'/'.join(variant)} against the MoM over the lobe, 1-D "
                               "surfaces. " + MAP_NOTE, 110), fontsize=7)
    # fixed margins (the labels' sizes are fixed): tight_layout measured every tick of the 25 maps (~3 CPU s)
    fig.subplots_adjust(left=0.09, right=0.99, bottom=0.03, top=0.935, wspace=0.06, hspace=0.08)
    save_figure(fig, path, dpi=90)
    return path


def maps(atlas, out):
    """One figure per graded element, with the errors written in: per material a (slope, height) x theta_i map."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = atlas.variants.index(("vgroove", "paper"))
    labels = [f"s {s:g}, h {h:g}" for s in atlas.slopes for h in atlas.heights]
    paths = []
    for e, name in enumerate(atlas.elements):
        codes, err = _codes_map(atlas, e, v)
        fig, axes = plt.subplots(1, len(atlas.materials), figsize=(3.0 * len(atlas.materials), 7.5), sharey=True,
                                 squeeze=False)
        for m, ax in enumerate(axes[0]):
            _draw_map(ax, atlas, codes[m], err[m])
            ax.set_title(atlas.materials[m], fontsize=8)
            ax.set_xlabel("theta_i (deg)", fontsize=7)
        axes[0, 0].set_yticks(range(len(labels)), labels, fontsize=5)
        fig.suptitle(f"Accuracy atlas, {ELEMENT_LABELS[name]} over the lobe, model vgroove/paper vs MoM (1-D surfaces); "
                     + MAP_NOTE + "; numbers: the error", fontsize=7)
        fig.tight_layout(rect=(0, 0, 1, 0.95))
        path = out / f"accuracy_atlas_maps_{name}.png"
        save_figure(fig, path, dpi=110)
        paths.append(path)
    return paths


def speed_chart(atlas, out):
    """Accuracy against time per method: each variant's seconds per evaluation against its median M00 error over
    the lobe and the share of atlas cells where it is adequate in every element; the MoM beside them."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tol = _tolerances(atlas)
    lobe = atlas.regions.index("lobe")
    err = atlas["error"][..., lobe].astype(float)          # [m, s, h, t, v, e]
    se = atlas["se"][..., lobe].astype(float)
    known = np.all(np.isfinite(err), axis=-1)
    rows = []
    for v, (sh, df) in enumerate(atlas.variants):
        ok = known[..., v]
        codes = verdict_codes(err[..., v, :], se[..., v, :], tol)
        adequate = np.all(codes == 0, axis=-1)[ok].mean()
        rows.append([f"{sh}/{df}", float(atlas["variant_cost_s"][v]), float(np.median(err[..., v, 0][ok])),
                     float(np.percentile(err[..., v, 0][ok], 90)), float(adequate), int(ok.sum())])
    runs = atlas["cpu_s"] > 0
    per_eval = atlas["cpu_s"][runs] / (atlas.theta_i.size * 359)
    mom_se = np.nanmedian(se[..., 0, 0])
    rows.append(["MoM (atlas settings)", float(np.median(per_eval)), float(mom_se), float(np.nanpercentile(se[..., 0, 0], 90)),
                 float(np.mean(atlas["status"] == 0)), int(runs.sum())])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for r in rows:
        mark = "s" if r[0].startswith("MoM") else "o"
        axes[0].loglog(r[1], max(r[2], 1e-3), mark, ms=7, label=r[0])
        axes[0].plot([r[1], r[1]], [max(r[2], 1e-3), max(r[3], 1e-3)], "-", color=axes[0].lines[-1].get_color(), lw=1)
        axes[1].semilogx(r[1], 100 * r[4], mark, ms=7)
        axes[1].annotate(r[0], (r[1], 100 * r[4]), fontsize=6, xytext=(3, 3), textcoords="offset points")
    axes[0].set(xlabel="seconds per evaluation", ylabel="M00 error over the lobe, dB (median; bar: 90th pct)",
                title="accuracy against time (MoM: its statistical error)")
    axes[0].legend(fontsize=6)
    axes[1].set(xlabel="seconds per evaluation", ylabel="% of cells adequate in every element",
                title="where each method is enough (1 dB, 0.1)")
    for ax in axes:
        ax.title.set_fontsize(9)
        ax.xaxis.label.set_fontsize(8)
        ax.yaxis.label.set_fontsize(8)
    fig.suptitle("Accuracy atlas, 1-D surfaces: model variants (3-D pbrdf, per direction pair) and the MoM (CPU s per "
                 "in-plane theta_i, theta_r, s and p; 'adequate' = converged)", fontsize=8)
    fig.tight_layout()
    save_figure(fig, out / "accuracy_atlas_speed.png")
    return rows


def table_csv(atlas, out):
    """accuracy_atlas.csv: per material, slope, height, theta_i and variant the lobe errors, standard errors and
    verdicts, the cell's status and coherent share."""
    tol = _tolerances(atlas)
    lobe = atlas.regions.index("lobe")
    header = ["material", "rms_slope", "sigma_h_wl", "theta_i_deg", "variant", "status", "coherent_share"]
    for e in atlas.elements:
        header += [f"{e}_error", f"{e}_se", f"{e}_verdict"]
    rows = []
    names = ("valid", "undecided", "invalid", "unknown")
    for (m, s, h, t), code in np.ndenumerate(atlas["status"]):
        for v, (sh, df) in enumerate(atlas.variants):
            err = atlas["error"][m, s, h, t, v, :, lobe].astype(float)
            se = atlas["se"][m, s, h, t, v, :, lobe].astype(float)
            row = [atlas.materials[m], atlas.slopes[s], atlas.heights[h], atlas.theta_i[t], f"{sh}/{df}",
                   atlas.status_names[code], f"{atlas['coherent'][m, s, h, t]:.4g}"]
            for e, c in enumerate(verdict_codes(err, se, tol)):
                row += [f"{err[e]:.4g}", f"{se[e]:.3g}", names[c]]
            rows.append(row)
    write_csv(out / "accuracy_atlas.csv", header, rows)
    return len(rows)


def _index(atlas, ck):
    task = json.loads(ck["task"])
    return (atlas.materials.index(task["material"]), int(np.argmin(np.abs(atlas.slopes - task["rms_slope"]))),
            int(np.argmin(np.abs(atlas.heights - task["height_wl"]))))


def reproduce(atlas):
    """Recompute the REPRODUCE cells: rows (key, same seeds, graded numbers, within, largest |difference| / its
    allowance); same seeds must give the table's numbers, new seeds agree within 2 combined standard errors."""
    from hyde_bsdf.mom import atlas as runs
    from hyde_bsdf.mom.atlas_errors import cell_errors

    by_key = {t["key"]: t for t in runs.tasks(mats=[m for m in runs.materials() if m.name == "PEC"])}
    rows = []
    for key, same in REPRODUCE:
        task = dict(by_key[key])
        if not same:
            task["seed"] += 50
        ck = runs.run_task(task)
        new = cell_errors(ck, atlas.variants)
        at = _index(atlas, {"task": json.dumps(task)})
        old_e, old_s = atlas["error"][at].astype(float), atlas["se"][at].astype(float)
        both = np.isfinite(old_e) & np.isfinite(new["error"])
        diff = np.abs(new["error"] - old_e)[both]
        tol = np.broadcast_to(_tolerances(atlas)[None, None, :, None], both.shape)[both]
        allowed = (1e-3 * np.maximum(1.0, np.abs(old_e[both])) if same      # float32 storage
                   else 2.0 * np.hypot(old_s[both], new["se"][both]) + 0.01 * tol)
        rows.append([key, same, int(both.sum()), float(np.mean(diff <= allowed)), float(np.max(diff / allowed)),
                     float(ck["cpu_s"])])
    return rows


def heldout(atlas, out):
    """The held-out runs (reused from OUTDIR/atlas_heldout, else run) against the atlas's stated errors there."""
    from hyde_bsdf.model.accuracy import accuracy
    from hyde_bsdf.mom import atlas as runs
    from hyde_bsdf.mom.atlas_errors import cell_errors

    folder = out / "atlas_heldout"
    run_heldout(folder, None, 2, progress=False)
    tol = _tolerances(atlas)
    lobe = atlas.regions.index("lobe")
    rows = []
    for key, ck in runs.load_checkpoints(folder).items():
        task = json.loads(ck["task"])
        true = cell_errors(ck, atlas.variants)
        for t, ti in enumerate(task["theta_i_deg"]):
            for v, (sh, df) in enumerate(atlas.variants):
                a = accuracy(math.radians(ti), task["rms_slope"], task["n"], task["k"], sigma_h_wl=task["height_wl"],
                             shadowing=sh, diffuse=df, atlas=atlas)
                for e, name in enumerate(atlas.elements):
                    stated = a.get("elements", {}).get(name, {})
                    te, ts = true["error"][t, v, e, lobe], true["se"][t, v, e, lobe]
                    rows.append([key, ti, f"{sh}/{df}", name, stated.get("error"), stated.get("se"),
                                 stated.get("valid"), float(te), float(ts), float(tol[e])])
    header = ["run", "theta_i_deg", "variant", "element", "stated_error", "stated_se", "stated_valid", "true_error",
              "true_se", "tolerance"]
    write_csv(out / "accuracy_atlas_heldout.csv", header, rows)
    graded = [r for r in rows if r[4] is not None and math.isfinite(r[7])]
    within = [r[7] <= r[4] + 2 * r[8] for r in graded]
    valid = [r for r in graded if r[6] is True]
    return dict(graded=len(graded), total=len(rows), within=float(np.mean(within)) if within else float("nan"),
                valid=len(valid), valid_ok=sum(r[7] <= r[9] for r in valid),
                worst_valid=max((r[7] / r[9] for r in valid), default=0.0))


def validate(outdir="out/validation", quick=False):
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    atlas = _atlas()
    maps_all(atlas, out / "accuracy_atlas_maps.png")
    if not quick:
        maps(atlas, out)
    speed = speed_chart(atlas, out)
    n_rows = table_csv(atlas, out)
    prov = atlas.provenance
    known = float(np.mean(atlas["status"] == 0))
    counts = ", ".join(f"{name} {int(np.sum(atlas['status'] == i))}" for i, name in enumerate(atlas.status_names)
                       if name != "ok" and np.any(atlas["status"] == i))
    checks = [dict(name="accuracy atlas: cells with an exact answer (the others unknown, by reason)",
                   value=f"{100 * known:.0f} % of {atlas['status'].size} ({counts}; {prov['mom']['cpu_s_total']:.0f} "
                         f"CPU s of MoM); {n_rows} CSV rows", tolerance="reported", passed=known > 0.0)]
    for r in speed:
        checks.append(dict(name=f"accuracy atlas: {r[0]}: seconds per evaluation; median / 90th pct M00 lobe error "
                                "(dB); share of cells adequate in every element", tolerance="reported", passed=True,
                           value=f"{r[1]:.2g} s; {r[2]:.2f} / {r[3]:.2f} dB; {100 * r[4]:.0f} % of {r[5]}"))
    for key, same, n, share, worst, cpu in reproduce(atlas):
        checks.append(dict(name=f"accuracy atlas: cell {key} recomputed with {'the same' if same else 'new'} seeds "
                                f"({cpu:.0f} CPU s): share of {n} graded numbers within "
                                + ("1e-3 of the table" if same else "2 combined standard errors (+ 1 % of the tolerance)"),
                           value=f"{100 * share:.1f} % (largest |diff| / allowance {worst:.2f})",
                           tolerance="100 %" if same else ">= 90 %", passed=share >= (1.0 if same else 0.9)))
    if not quick:
        h = heldout(atlas, out)
        checks.append(dict(name="accuracy atlas held-out (surfaces, angles and Ag off the grid): true error within "
                                "the stated error + 2 standard errors", value=f"{100 * h['within']:.1f} % of "
                                f"{h['graded']} graded numbers ({h['total'] - h['graded']} unknown)",
                           tolerance=">= 90 %", passed=h["within"] >= 0.9))
        checks.append(dict(name="accuracy atlas held-out: numbers the atlas calls valid that are within the tolerance",
                           value=f"{h['valid_ok']} of {h['valid']} (largest true error / tolerance "
                                 f"{h['worst_valid']:.2f})", tolerance="all", passed=h["valid_ok"] == h["valid"]))
    return checks


def heldout_materials():
    """The held-out materials: the atlas's PEC and Al at 633 nm, and Ag at 633 nm (Mitsuba's table), which the
    atlas has not."""
    from hyde_bsdf.mom import atlas as runs

    mats = {m.name: m for m in runs.materials()}
    n, k = runs._mitsuba_index("Ag", 633.0)
    mats["Ag_633nm"] = runs.Material("Ag_633nm", n, k, "silver at 633 nm, Mitsuba data/ior Ag (linear)")
    return [mats[name] for name in HELDOUT_MATERIALS]


def run_heldout(folder, executor, workers, progress=True):
    """The held-out MoM runs into ``folder`` (those not there yet); returns how many ran."""
    from hyde_bsdf.mom import atlas as runs

    mats = heldout_materials()
    grid = runs.Grid(theta_i_deg=HELDOUT_THETA_I)
    todo = runs.tasks(grid, mats=mats, surfaces=HELDOUT_SURFACES, seed_base=HELDOUT_SEED_BASE)
    return runs.run_tasks(todo, folder, executor=executor, workers=workers, grid=grid, mats=mats, progress=progress)


def _executor(args):
    if not args.dask:
        return None
    try:
        from distributed import Client
    except ImportError:
        raise SystemExit("--dask needs the 'distributed' package: pip install 'hyde-bsdf[distributed]'") from None
    return Client(args.dask).get_executor()


BUILD = ("run", "table", "heldout")


def build(argv):
    """The generation's command line (``run``, ``table``, ``heldout``: the module docstring)."""
    repo = Path(__file__).resolve().parents[2]
    ap = argparse.ArgumentParser(prog="accuracy_atlas.py", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    for name, default in (("run", "out/atlas_runs"), ("heldout", "out/atlas_heldout"), ("table", "out/atlas_runs")):
        p = sub.add_parser(name)
        p.add_argument("--checkpoints", default=default, help=f"checkpoint folder (default {default})")
        if name == "table":
            p.add_argument("-o", "--output", default=str(repo / "hyde_bsdf" / "data" / "accuracy_atlas.npz"))
        else:
            p.add_argument("--workers", type=int, default=2, help="process-pool workers (default 2)")
            p.add_argument("--dask", metavar="ADDRESS", help="run the tasks on this dask scheduler instead")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.command == "table":
        from hyde_bsdf.mom import atlas_errors

        print(f"wrote {atlas_errors.write_table(args.checkpoints, args.output)} in {time.perf_counter() - t0:.0f} s")
        return 0
    if args.command == "heldout":
        n = run_heldout(args.checkpoints, _executor(args), args.workers)
    else:
        from hyde_bsdf.mom import atlas as runs

        n = runs.run_tasks(runs.tasks(), args.checkpoints, executor=_executor(args), workers=args.workers)
    print(f"ran {n} tasks in {time.perf_counter() - t0:.0f} s wall; checkpoints in {args.checkpoints}")
    return 0


def main():
    """``run``/``table``/``heldout`` build the atlas; anything else is the validation's own command line."""
    if len(sys.argv) > 1 and sys.argv[1] in BUILD:
        return build(sys.argv[1:])
    cli(validate, __doc__)


if __name__ == "__main__":
    cli(validate, __doc__, main)
