"""Inverse rendering of (rms_slope, eta, k) of the ``hyde`` BSDF from a Stokes image.

Part A (recovery): the scene of hyde_bsdf/data/scenes/inverse.xml (a sphere under two point lights,
facet angles beta ~ 10-70 deg), a noise-free reference (512 spp, seed 0) at
TRUTH = (rms_slope 0.3, eta 1.5, k 3.0), Adam from START = (0.6, 3.0, 6.0) with the
loss on all four Stokes components, and for comparison with the S0 loss alone.
Pass: rms_slope within 2 %, n (= eta) and k within 5 %.

Part B (identifiability): one directional light at a 120 deg phase angle, so every
pixel sees nearly one facet angle beta = 60 deg.  S0 then holds one reflectance
number for two unknowns: its loss has a valley of exact solutions in (n, k); with
S1-S3 the linear polarization |r_s|^2 - |r_p|^2 adds the second equation.  Both
losses are optimized from START, and both loss landscapes over (n, k) (rms_slope at
the truth; reference and renders with the same seed, so the truth has loss 0) are
mapped.  (At beta = 45 deg even the full Stokes image would not do: there
|r_p|^2 = |r_s|^4 for every index (Abeles), so S1 follows from S0.)

Writes to OUTDIR (default out/validation/): inverse_render.png, inverse_render.csv
(final values and errors), inverse_history_<scene>_<loss>.csv (trajectories),
inverse_identifiability.png, inverse_landscape.csv, inverse_valley.csv,
inverse_endpoints.csv.

    python hyde_bsdf/validation/inverse_render.py [-o OUTDIR] [--iterations 400]
                                        [--iterations-directional 1000] [--quick]
"""
from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

from hyde_bsdf import inverse as inv
from hyde_bsdf.io.atomic import atomic_open

from hyde_bsdf.validation._common import cli, save_figure  # noqa: E402
from hyde_bsdf.progress import stderr_lines  # noqa: E402

_log = stderr_lines("[invert]")
#: the quick mode's variant: its step can be frozen (see :func:`validate`)
QUICK_VARIANT = "llvm_ad_mono_polarized"


def recovery(out, iterations, spp, spp_ref, res, lighting, tag, runs=("stokes", "s0"), lr=0.05, freeze=False):
    """Reference at TRUTH, then one Adam run per loss from START (``freeze``: a frozen step, :func:`invert`)."""
    scene = inv.scalar.load_scene(None, res=res, spp=spp, lighting=lighting)
    if not runs:        # the scene alone (quick mode's part B)
        return scene, None, {}
    ref = inv.scalar.render_reference(scene, inv.scalar.TRUTH, spp_ref, seed=0)
    results = {}
    for comp in runs:
        _log(f"[{tag}] {comp} loss, {iterations} iterations")
        loss_fn = inv.StokesLoss(ref, components=comp)
        res_ = inv.invert(scene, loss_fn, inv.scalar.START, iterations=iterations, spp=spp, seed=1000,
                          truth=inv.scalar.TRUTH, lr=lr, freeze=freeze)
        res_.write_history(out / f"inverse_history_{tag}_{comp}.csv")
        results[comp] = res_
    return scene, ref, results


def landscape(scene, spp, grid_n=15, seed=7):
    """log10 of both losses over (eta, k) at the true rms_slope; common random numbers."""
    ref = inv.scalar.render_reference(scene, inv.scalar.TRUTH, spp, seed=seed)
    losses = {c: inv.StokesLoss(ref, components=c) for c in ("s0", "stokes")}
    etas = np.exp(np.linspace(np.log(0.5), np.log(8.0), grid_n))
    ks = np.exp(np.linspace(np.log(1.0), np.log(10.0), grid_n))
    maps = {c: np.zeros((grid_n, grid_n)) for c in losses}
    for i, e in enumerate(etas):
        for j, k in enumerate(ks):
            S = inv.scalar.render_reference(scene, {"rms_slope": inv.scalar.TRUTH["rms_slope"], "eta": e, "k": k}, spp, seed=seed)
            for c, fn in losses.items():
                maps[c][i, j] = fn.numpy(S)
        print(f"\r[landscape] {i + 1}/{grid_n} rows", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return etas, ks, maps


def valley_profile(scene, spp, seed=7, points=13):
    """Both losses along the curve of equal facet reflectance A(beta = 60 deg) through the truth.

    The curve k(eta) solves A(60 deg; eta, k) = A(60 deg; truth) with the NumPy Fresnel terms
    (:mod:`hyde_bsdf.model.fresnel`); along it the S0 image barely changes (one facet angle), so the
    S0 loss stays at its floor while the Stokes loss, which also sees |r_s|^2 - |r_p|^2, rises.
    """
    from scipy.optimize import brentq

    from hyde_bsdf.model.fresnel import fresnel_mueller_terms
    from hyde_bsdf.model.index import Index

    c = np.cos(np.radians(60.0))
    A = lambda e, k: float(fresnel_mueller_terms(np.array(c), Index(e, k))[0])
    target = A(inv.scalar.TRUTH["eta"], inv.scalar.TRUTH["k"])
    ref = inv.scalar.render_reference(scene, inv.scalar.TRUTH, spp, seed=seed)
    losses = {comp: inv.StokesLoss(ref, components=comp) for comp in ("s0", "stokes")}
    rows = []
    for e in np.exp(np.linspace(np.log(0.6), np.log(6.0), points)):
        try:
            k = brentq(lambda kk: A(e, kk) - target, 0.01, 40.0)
        except ValueError:       # no k gives this reflectance at this eta
            continue
        S = inv.scalar.render_reference(scene, {"rms_slope": inv.scalar.TRUTH["rms_slope"], "eta": e, "k": k}, spp, seed=seed)
        rows.append({"eta": e, "k": k, "loss_s0": losses["s0"].numpy(S), "loss_stokes": losses["stokes"].numpy(S)})
    return rows


def endpoint_losses(scene, runs, spp, spp_ref, seed=7):
    """Both losses at the truth and at each run's end point (same seed as the reference: no
    sampling noise), and the noise floor an iteration sees (a 16-spp render at the truth
    against the high-spp reference)."""
    ref_crn = inv.scalar.render_reference(scene, inv.scalar.TRUTH, spp, seed=seed)
    ref_hi = inv.scalar.render_reference(scene, inv.scalar.TRUTH, spp_ref, seed=0)
    rows = []
    points = {"truth": inv.scalar.TRUTH, **{f"end of {c} run": r.final for c, r in runs.items()}}
    for label, values in points.items():
        S = inv.scalar.render_reference(scene, values, spp, seed=seed)
        row = {"point": label, **{p: values[p] for p in inv.PARAMETERS}}
        for comp in ("s0", "stokes"):
            row[f"loss_{comp}"] = inv.StokesLoss(ref_crn, components=comp).numpy(S)
        rows.append(row)
    S = inv.scalar.render_reference(scene, inv.scalar.TRUTH, spp, seed=seed + 1)
    rows.append({"point": f"noise floor ({spp} spp vs {spp_ref} spp reference)",
                 **{p: inv.scalar.TRUTH[p] for p in inv.PARAMETERS},
                 **{f"loss_{c}": inv.StokesLoss(ref_hi, components=c).numpy(S) for c in ("s0", "stokes")}})
    return rows


def _write_dicts(path, comment, rows):
    """A CSV of dict rows (floats to 6 digits) under one ``# comment`` line, written atomically."""
    with atomic_open(path, "w", newline="") as fh:
        fh.write(f"# {comment}\n")
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def validate(outdir="out/validation", quick=False, iterations=400, iterations_directional=1000, spp=16,
             spp_ref=512, res=64):
    """Run parts A and B; write the PNG/CSV files; return the report's checks.

    ``quick`` (the report's quick mode, ~8 CPU s): part A at 32 x 32 px with the Stokes loss only
    (180 iterations, learning rate 0.12), part B without the two 1000-iteration runs (landscape 5 x 5, the valley
    profile and the end-point losses at the truth only); in ``llvm_ad_mono_polarized`` with a frozen step
    (``dr.freeze``, which Dr.Jit cannot record in the spectral variant): the lights are white and the index does
    not depend on the wavelength, so one wavelength holds all the information (as in svbrdf_inverse.py), and the
    180 iterations cost 5 CPU s instead of 17 (measured: errors +0.26 / -1.10 / -0.90 % spectral, -0.76 / +0.82 /
    +0.48 % mono; the same tolerances).  The full run stays spectral and unfrozen.
    """
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    it, itd, grid_n = iterations, iterations_directional, 15
    runs_a, runs_b, lr_a = ("stokes", "s0"), ("stokes", "s0"), 0.05
    variant, freeze = inv.scalar.VARIANT, False
    if quick:
        it, res, grid_n, runs_a, runs_b, lr_a = 180, 32, 5, ("stokes",), (), 0.12
        variant, freeze = QUICK_VARIANT, True
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t0 = time.perf_counter()
    inv.prepare(variant)
    _, refA, A = recovery(out, it, spp, spp_ref, res, "points", "points", runs_a, lr=lr_a, freeze=freeze)
    sceneB, _, B = recovery(out, itd, spp, spp_ref, res, "directional", "directional", runs_b)
    etas, ks, maps = landscape(sceneB, spp, grid_n)
    valley = valley_profile(sceneB, spp, points=7 if quick else 13)
    ends = endpoint_losses(sceneB, B, spp, spp_ref)
    _write_dicts(out / "inverse_endpoints.csv", "directional light (beta = 60 deg): both losses at the truth and at "
                 "the end points of the two runs, rendered with the reference's seed (no sampling noise between them)",
                 ends)
    _write_dicts(out / "inverse_valley.csv", "directional light (beta = 60 deg): losses along the curve of equal "
                 "facet reflectance A(60 deg) through the truth; rms_slope at truth; same seed for reference and "
                 "renders", valley)

    rows = []
    for tag, runs in (("points", A), ("directional", B)):
        for comp, r in runs.items():
            for p in inv.PARAMETERS:
                err = (r.final[p] - inv.scalar.TRUTH[p]) / inv.scalar.TRUTH[p]
                tol = 0.02 if p == "rms_slope" else 0.05
                rows.append({"scene": tag, "loss": comp, "parameter": p, "truth": inv.scalar.TRUTH[p],
                             "start": inv.scalar.START[p], "final": r.final[p], "rel_error": err,
                             "tolerance": tol, "within": abs(err) <= tol,
                             "final_loss": r.history[-1]["loss"],
                             "s_per_iteration": r.seconds_per_iteration})
    with atomic_open(out / "inverse_render.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    with atomic_open(out / "inverse_landscape.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        fh.write("# directional light, phase 120 deg; rms_slope at truth; loss vs (eta, k); same seed "
                 "for reference and renders\n")
        w.writerow(["eta", "k", "loss_s0", "loss_stokes"])
        for i, e in enumerate(etas):
            for j, k in enumerate(ks):
                w.writerow([f"{e:.5g}", f"{k:.5g}", f"{maps['s0'][i, j]:.6e}", f"{maps['stokes'][i, j]:.6e}"])

    # ---- figure 1: trajectories of the main scene + reference Stokes images
    fig, axes = plt.subplots(2, 4, figsize=(16, 7))
    for c, (comp, r) in enumerate(A.items()):
        itx = [h["iteration"] for h in r.history]
        axes[0, 0].semilogy(itx, [h["loss"] for h in r.history], f"C{c}-", lw=1, label=f"{comp} loss")
        for a, p in zip(axes[0, 1:], inv.PARAMETERS):
            a.plot(itx, [h[p] for h in r.history], f"C{c}-", lw=1.2,
                   label=f"{comp}: {r.final[p]:.4g} ({100 * (r.final[p] / inv.scalar.TRUTH[p] - 1):+.2f} %)")
    for a, p in zip(axes[0, 1:], inv.PARAMETERS):
        a.axhline(inv.scalar.TRUTH[p], color="k", ls="--", lw=0.8)
        a.set_title(f"{p} (dashed: truth {inv.scalar.TRUTH[p]})")
        a.legend(fontsize=7)
        a.set_xlabel("iteration")
    axes[0, 0].set_title("loss (own normalization)")
    axes[0, 0].legend(fontsize=7)
    axes[0, 0].set_xlabel("iteration")
    for a, s, name in zip(axes[1], refA, ("S0", "S1", "S2", "S3")):
        vmax = float(np.abs(s).max()) or 1.0
        im = a.imshow(s, cmap="gray" if name == "S0" else "RdBu", vmin=0 if name == "S0" else -vmax, vmax=vmax)
        a.set_title(f"reference {name} (luminance)")
        a.axis("off")
        fig.colorbar(im, ax=a, fraction=0.046)
    fig.suptitle(f"hyde inverse rendering, sphere under two point lights ({res}x{res}, {spp} spp/it, Adam, {variant}); "
                 f"truth {inv.scalar.TRUTH}, start {inv.scalar.START}", fontsize=9)
    # the margins tight_layout chose for these labels, fixed: it measured every tick label again (~0.3 CPU s)
    fig.subplots_adjust(left=0.036, right=0.958, bottom=0.034, top=0.907, wspace=0.18, hspace=0.298)
    save_figure(fig, out / "inverse_render.png", dpi=110)

    # ---- figure 2: identifiability (directional light)
    fig, axes = plt.subplots(1, 5, figsize=(22, 4.2))
    for a, comp in zip(axes[:2], ("s0", "stokes")):  # maps[comp][i_eta, j_k]
        im = a.pcolormesh(ks, etas, np.log10(maps[comp] + 1e-12), shading="auto", cmap="viridis")
        a.set_xscale("log")
        a.set_yscale("log")
        a.plot(inv.scalar.TRUTH["k"], inv.scalar.TRUTH["eta"], "r*", ms=12, label="truth")
        if comp in B:
            hist = B[comp].history
            a.plot([h["k"] for h in hist], [h["eta"] for h in hist], "w-", lw=0.8, label="Adam path")
            a.plot(B[comp].final["k"], B[comp].final["eta"], "wo", ms=5, label="end")
        a.set_xlabel("k")
        a.set_ylabel("eta (= n)")
        a.set_title(f"log10 {comp} loss over (n, k), rms_slope = truth")
        a.legend(fontsize=7)
        fig.colorbar(im, ax=a)
    for c, comp in enumerate(c_ for c_ in ("s0", "stokes") if c_ in B):
        r = B[comp]
        itx = [h["iteration"] for h in r.history]
        for a, p in zip(axes[2:], ("eta", "k")):
            a.plot(itx, [h[p] for h in r.history], f"C{c}-",
                   label=f"{comp} loss: {r.final[p]:.3g} ({100 * (r.final[p] / inv.scalar.TRUTH[p] - 1):+.1f} %)")
    for a, p in zip(axes[2:4], ("eta", "k")):
        a.axhline(inv.scalar.TRUTH[p], color="k", ls="--", lw=0.8)
        a.set_title(f"{p}: directional light, phase 120 deg" + ("" if B else " (runs skipped: quick mode)"))
        a.set_xlabel("iteration")
        if B:
            a.legend(fontsize=7)
    ve = [r["eta"] for r in valley]
    axes[4].semilogy(ve, [r["loss_s0"] for r in valley], "C0o-", label="S0 loss")
    axes[4].semilogy(ve, [r["loss_stokes"] for r in valley], "C1s-", label="Stokes loss")
    axes[4].axvline(inv.scalar.TRUTH["eta"], color="k", ls="--", lw=0.8)
    axes[4].set_xscale("log")
    axes[4].set_xlabel("eta along the curve A(60 deg; eta, k) = A(60 deg; truth)")
    axes[4].set_title("losses along the S0 valley", fontsize=9)
    axes[4].legend(fontsize=7)
    fig.suptitle("identifiability: one facet angle (beta = 60 deg); S0 alone fixes one combination "
                 "of n and k, S1-S3 fix both", fontsize=9)
    # the margins tight_layout chose for these labels, fixed: it measured every tick label again (~0.3 CPU s)
    fig.subplots_adjust(left=0.046, right=0.988, bottom=0.145, top=0.844, wspace=0.315)
    save_figure(fig, out / "inverse_identifiability.png", dpi=110)

    checks = []
    for r in rows:
        if r["loss"] == "stokes":
            checks.append(dict(name=f"{r['scene']} scene, Stokes loss, {res}x{res} px: {r['parameter']} recovered "
                                    f"from {r['start']:g} (truth {r['truth']:g})",
                               value=f"{r['final']:.5g} ({100 * r['rel_error']:+.2f} %)",
                               tolerance=f"+-{100 * r['tolerance']:g} %", passed=bool(r["within"])))
    if "s0" in B:
        worst = max(abs(r["rel_error"]) for r in rows
                    if r["scene"] == "directional" and r["loss"] == "s0" and r["parameter"] in ("eta", "k"))
        checks.append(dict(name="directional scene (one facet angle), S0 loss alone: n, k not identified "
                                "(largest error of eta, k)", value=f"{100 * worst:.0f} %", tolerance="> 20 %",
                           passed=worst > 0.2))
        end = next(r for r in ends if r["point"] == "end of s0 run")
        floor = ends[-1]
        checks.append(dict(name="at the S0 run's end point: Stokes loss / its per-iteration noise floor "
                                "(S0 loss / its floor in brackets)",
                           value=f"{end['loss_stokes'] / floor['loss_stokes']:.0f} "
                                 f"({end['loss_s0'] / floor['loss_s0']:.2f})",
                           tolerance="> 10 (< 1)",
                           passed=end["loss_stokes"] > 10 * floor["loss_stokes"] and end["loss_s0"] < floor["loss_s0"]))
    ratios = [v["loss_stokes"] / v["loss_s0"] for v in valley if abs(v["eta"] / inv.scalar.TRUTH["eta"] - 1) > 0.1]
    checks.append(dict(name="directional scene, along the S0 valley A(60 deg) = const: Stokes loss / S0 loss "
                            "(smallest over the points away from the truth)",
                       value=f"{min(ratios):.1f}", tolerance="> 10", passed=min(ratios) > 10))
    print(f"{'scene':12s} {'loss':7s} {'param':10s} {'truth':>7s} {'final':>9s} {'error':>8s}  ok")
    for r in rows:
        print(f"{r['scene']:12s} {r['loss']:7s} {r['parameter']:10s} {r['truth']:7.4g} {r['final']:9.5g} "
              f"{100 * r['rel_error']:+7.2f}%  {'yes' if r['within'] else 'NO'}")
    print("directional scene, losses without sampling noise:")
    for r in ends:
        print(f"  {r['point']:45s} S0 loss {r['loss_s0']:.3g}   Stokes loss {r['loss_stokes']:.3g}")
    print(f"s/iteration (stokes loss, points scene): {A['stokes'].seconds_per_iteration:.3f}; "
          f"total {time.perf_counter() - t0:.0f} s; wrote {out}/inverse_*.png/csv")
    return checks


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("-o", "--outdir", default="out/validation")
    ap.add_argument("--iterations", type=int, default=400, help="Adam iterations, two-light scene")
    ap.add_argument("--iterations-directional", type=int, default=1000,
                    help="Adam iterations, directional scene (its Stokes valley is long and narrow)")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--spp-ref", type=int, default=512)
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--quick", action="store_true", help="the report's quick mode (~25 s)")
    args = ap.parse_args(argv)
    checks = validate(args.outdir, quick=args.quick, iterations=args.iterations,
                      iterations_directional=args.iterations_directional, spp=args.spp, spp_ref=args.spp_ref,
                      res=args.res)
    for c in checks:
        print(f"[{'pass' if c['passed'] else 'FAIL'}] {c['name']}: {c['value']} (tolerance {c['tolerance']})")
    return 0 if all(c["passed"] for c in checks) else 1


if __name__ == "__main__":
    cli(validate, __doc__, main)
