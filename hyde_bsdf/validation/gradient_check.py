"""AD gradients of a rendered Stokes loss against central finite differences.

Scene: hyde_bsdf/data/scenes/inverse.xml's sphere under two point lights (hyde_bsdf.inverse.scalar.scene_dict),
llvm_ad_spectral_polarized, ``stokes`` around ``path``.  Loss: the Stokes loss of
hyde_bsdf.inverse against a reference at (rms_slope 0.3, eta 1.5, k 3.0), evaluated at
(0.4, 2.0, 4.0).  For each seed the AD gradient (``dr.backward`` through
``mi.render(scene, params, seed=s)``) is compared with a central difference of the
same loss rendered with the **same seed** at +-h (relative step ``--rel-step``), so
the Monte-Carlo noise largely cancels between the two; over several seeds we also
compare the means (their difference should be within the standard error).  Both
with the diffuse term on (``diffuse="paper"``: the rms_slope gradient then also
flows through the DHR table texture, 1 - rho(theta, rms_slope)) and off.

Writes OUTDIR/gradient_check.png and OUTDIR/gradient_check.csv.

    python hyde_bsdf/validation/gradient_check.py [-o OUTDIR] [--seeds 4] [--res 48] [--spp 16]
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

AT = {"rms_slope": 0.4, "eta": 2.0, "k": 4.0}


def check(diffuse, seeds, res, spp, rel_step):
    scene = inv.scalar.load_scene(None, res=res, spp=spp, diffuse=diffuse)
    ref = inv.scalar.render_reference(scene, inv.scalar.TRUTH, 256, seed=0)
    loss_fn = inv.StokesLoss(ref, components="stokes")
    rows = []
    for s in range(1, seeds + 1):
        _, ad = inv.scalar.loss_and_gradient(scene, loss_fn, AT, spp=spp, seed=s, seed_grad=s)
        _, ad_dec = inv.scalar.loss_and_gradient(scene, loss_fn, AT, spp=spp, seed=s)
        for p in inv.PARAMETERS:
            fd = inv.scalar.finite_difference_gradient(scene, loss_fn, AT, p, rel_step=rel_step, spp=spp, seed=s)
            rows.append({"diffuse": diffuse, "seed": s, "parameter": p, "ad": ad[p], "fd": fd,
                         "rel_diff": (ad[p] - fd) / abs(fd), "ad_decorrelated": ad_dec[p],
                         "rel_diff_decorrelated": (ad_dec[p] - fd) / abs(fd)})
        print(f"\r[gradient] diffuse={diffuse}: seed {s}/{seeds}", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return rows


def validate(outdir="out/validation", quick=False, seeds=4, res=48, spp=16, rel_step=1e-2):
    """AD vs FD for both diffuse settings; write the PNG/CSV; return the report's checks.

    ``quick``: 3 seeds on 32 x 32 px.
    """
    if quick:
        seeds, res = 3, 32
    args = argparse.Namespace(seeds=seeds, res=res, spp=spp, rel_step=rel_step)
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    inv.prepare()
    t0 = time.perf_counter()
    rows = check("paper", args.seeds, args.res, args.spp, args.rel_step) + \
        check("none", args.seeds, args.res, args.spp, args.rel_step)
    with atomic_open(out / "gradient_check.csv", "w", newline="") as fh:
        fh.write(f"# loss at {AT}, reference at {inv.scalar.TRUTH}; {args.res}x{args.res}, {args.spp} spp; "
                 f"central differences with relative step {args.rel_step}, same seed as the AD render\n")
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    summary = []
    for a, diffuse in zip(axes, ("paper", "none")):
        for i, p in enumerate(inv.PARAMETERS):
            sel = [r for r in rows if r["diffuse"] == diffuse and r["parameter"] == p]
            ad = np.array([r["ad"] for r in sel])
            dec = np.array([r["ad_decorrelated"] for r in sel])
            fd = np.array([r["fd"] for r in sel])
            scale = np.abs(fd.mean())
            se = lambda x: x.std(ddof=1) / np.sqrt(len(x)) if len(x) > 1 else 0.0
            a.errorbar(i - 0.15, ad.mean() / scale, yerr=se(ad) / scale, fmt="o", color="C0",
                       label="AD, same seed as FD" if i == 0 else None)
            a.errorbar(i, fd.mean() / scale, yerr=se(fd) / scale, fmt="s", color="C1",
                       label="central FD" if i == 0 else None)
            a.errorbar(i + 0.15, dec.mean() / scale, yerr=se(dec) / scale, fmt="^", color="C2",
                       label="AD, mi.render's decorrelated gradient pass" if i == 0 else None)
            per_seed = np.abs((ad - fd) / fd)
            z = (dec.mean() - fd.mean()) / max(np.hypot(se(dec), se(fd)), 1e-300)
            summary.append((diffuse, p, ad.mean(), fd.mean(), per_seed.max(), dec.mean(), se(dec), z))
            a.annotate(f"same seed: max {100 * per_seed.max():.3f} %\ndecorrelated: {z:+.1f} SE",
                       (i, 0.35), ha="center", fontsize=7)
        a.set_xticks(range(3), inv.PARAMETERS)
        a.axhline(0, color="k", lw=0.5)
        a.set_ylabel("gradient / |mean FD gradient| (signed)")
        a.set_title(f"diffuse={diffuse!r}" + (" (rms_slope also through the DHR texture)"
                                              if diffuse == "paper" else ""), fontsize=9)
        a.legend(fontsize=7, loc="lower left")
    fig.suptitle(f"dL/dparameter of a rendered Stokes loss at {AT}: AD vs finite differences "
                 f"({args.res}x{args.res}, {args.spp} spp, seeds 1..{args.seeds}; error bars: standard error "
                 f"over seeds)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "gradient_check.png", dpi=110)
    print(f"{'diffuse':8s} {'param':10s} {'AD(same seed)':>14s} {'FD':>12s} {'max rel diff':>13s} "
          f"{'AD(decorr.) +- SE':>24s} {'z':>6s}")
    for d, p, a_, f_, m, dm, dse, z in summary:
        print(f"{d:8s} {p:10s} {a_:14.6g} {f_:12.6g} {100 * m:12.3f}% {dm:14.6g} +- {dse:.2g} {z:+6.2f}")
    print(f"({time.perf_counter() - t0:.0f} s) wrote {out}/gradient_check.png/csv")
    checks = []
    for d, p, a_, f_, m, dm, dse, z in summary:
        checks.append(dict(name=f"dL/d{p} (diffuse {d}): AD on the FD's samples vs central FD, worst of "
                                f"{args.seeds} seeds", value=f"{100 * m:.3f} %", tolerance="< 0.5 %",
                           passed=m < 0.005))
        checks.append(dict(name=f"dL/d{p} (diffuse {d}): mi.render's decorrelated AD pass vs FD, mean over "
                                f"{args.seeds} seeds", value=f"{dm:.5g} vs {f_:.5g} (z = {z:+.2f})",
                           tolerance="|z| < 3", passed=abs(z) < 3))
    return checks


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("-o", "--outdir", default="out/validation")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--rel-step", type=float, default=1e-2)
    ap.add_argument("--quick", action="store_true", help="the report's quick mode")
    a = ap.parse_args(argv)
    checks = validate(a.outdir, quick=a.quick, seeds=a.seeds, res=a.res, spp=a.spp, rel_step=a.rel_step)
    return 0 if all(c["passed"] for c in checks) else 1


if __name__ == "__main__":
    cli(validate, __doc__, main)
