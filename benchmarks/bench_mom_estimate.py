"""The MoM's cost estimate (hyde_bsdf.mom.estimate, hyde_bsdf/mom/cost.py) against measured runs: ratios.

Runs single partitions of the fast solver over surfaces, materials, samplings and incidence counts (one core,
in process), and prints per run the measured CPU seconds of each stage (set-up, solve, far field) beside the
estimate, and the ratio measured / estimated of the total.  ``--fit`` also prints the least-squares constants
of the cost model (copy them into hyde_bsdf/resources.py's COSTS, fast_fill_seconds_per_entry ...
far_field_seconds, after a change to the solver).

    .venv/bin/python benchmarks/bench_mom_estimate.py [--fit] [--quick] [--atlas out/atlas_runs]
"""
from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

#: (label, partition length, sigma_h, ell, pts_per_wl, n, k, incidence angles)
CASES = [
    ("PEC slope 0.35", 300, 1.0, 4.04, 10, None, None, 10),
    ("PEC rough, long blocks", 600, 4.0, 20.0, 10, None, None, 10),
    ("PEC 20 pts/wl", 300, 1.0, 4.04, 20, None, None, 10),
    ("PEC 2 angles", 300, 1.0, 4.04, 10, None, None, 2),
    ("PEC slope 0.7", 300, 2.0, 4.04, 15, None, None, 10),
    ("Au 633 nm", 300, 1.0, 4.04, 10, 0.18, 3.07, 10),
    ("Al 633 nm", 300, 1.0, 4.04, 10, 1.37, 7.62, 10),
    ("Al 1550 nm", 300, 1.0, 4.04, 10, 1.5, 15.0, 10),
    ("glass", 300, 1.0, 4.04, 10, 1.5, 0.0, 10),
    ("glass rough", 300, 2.0, 8.0, 10, 1.5, 0.0, 10),
]
QUICK = (0, 3, 6, 8)


def run(case):
    from hyde_bsdf import mom

    label, length, sh, ell, ppw, n, k, n_ti = case
    ti = list(np.linspace(0, 85, n_ti))
    tr = np.arange(-89.5, 89.6, 0.5)
    kw = dict(pts_per_wl=ppw, seed=7, polarization=("s", "p"), n=n, k=k)
    est = mom.estimate(length, 1, sh, ell, ti, tr, workers=1, **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mom.MoMAccuracyWarning)
        res = mom.scatter(length, 1, sh, ell, ti, tr, executor=mom.SerialExecutor(), progress=False, **kw)
    t = res.times
    return est, (t["fill"] + t["factor"], t["solve"], t["far_field"])


def fit(rows):
    """Least-squares constants (non-negative) of the three stages from the measured runs."""
    from scipy.optimize import nnls

    A_set, b_set, A_sol, b_sol, A_far, b_far = [], [], [], [], [], []
    for est, meas in rows:
        f, n, strong = est["features"], est["features"]["n"], 3 * est["features"]["block"]
        A_set.append([n * strong * f["regions"], n * strong * f["panels"], n * f["waves"]])
        b_set.append(meas[0])
        A_sol.append([n * est["n_rhs"] * strong * f["regions"], n * est["n_rhs"] * f["waves"] * f["regions"]])
        b_sol.append(meas[1])
        A_far.append([n * est["n_far"] * est["n_rhs"]])
        b_far.append(meas[2])
    out = {}
    for names, A, b in ((("a_fill", "a_panel", "a_wave"), A_set, b_set), (("a_band", "a_sweep"), A_sol, b_sol),
                        (("a_far",), A_far, b_far)):
        A, b = np.array(A, float), np.array(b, float)
        scale = A.max(axis=0)
        x, _ = nnls(A / scale / b[:, None], np.ones_like(b))    # relative errors
        out.update({nm: float(v / s) for nm, v, s in zip(names, x, scale)})
    return out


def against_atlas(folder):
    """Out of sample: the estimate of each atlas run's pilot partition (its surface, index, angles, sampling)
    against the CPU seconds it took (checkpoints of hyde_bsdf/validation/accuracy_atlas.py run)."""
    import json

    from hyde_bsdf import mom
    from hyde_bsdf.mom import atlas

    ratios = {}
    for key, ck in atlas.load_checkpoints(folder).items():
        t = json.loads(ck["task"])
        tr = atlas.Grid(theta_r_step_deg=t["theta_r_step_deg"]).theta_r_deg()
        est = mom.estimate(t["partition_wl"], 1, t["height_wl"], t["corr_length_wl"], t["theta_i_deg"], tr,
                           pts_per_wl=t["pts_per_wl"], seed=t["seed"], workers=1, polarization=("s", "p"),
                           n=t["n"], k=t["k"])
        ratios.setdefault(t["material"], []).append(float(ck["cpu_per_partition"]) / est["cpu_seconds"])
    every = np.concatenate([np.array(v) for v in ratios.values()])
    for name, v in ratios.items():
        v = np.array(v)
        print(f"atlas pilots, {name:10s} {v.size:3d} runs: measured / estimated median {np.median(v):.2f}, "
              f"10-90 % {np.percentile(v, 10):.2f}-{np.percentile(v, 90):.2f}")
    print(f"atlas pilots, all {every.size} runs: median {np.median(every):.2f}, 10-90 % {np.percentile(every, 10):.2f}-"
          f"{np.percentile(every, 90):.2f}, within a factor 2: {100 * np.mean(np.abs(np.log2(every)) <= 1):.0f} %")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fit", action="store_true", help="print the fitted constants of the cost model")
    ap.add_argument("--quick", action="store_true", help="four cases only")
    ap.add_argument("--atlas", metavar="DIR", help="also compare with the pilot partitions of the atlas's "
                    "checkpoints in DIR (out of sample)")
    args = ap.parse_args(argv)
    if args.atlas:
        against_atlas(args.atlas)
    from hyde_bsdf.mom import cost

    cases = [CASES[i] for i in QUICK] if args.quick else CASES
    rows, ratios = [], []
    print(f"{'case':26s} {'N':>6s} {'B':>4s} {'Q':>5s} {'p':>3s}  measured set-up/solve/far (s)   estimated        ratio")
    for case in cases:
        est, meas = run(case)
        rows.append((est, meas))
        guess = cost.fast_seconds(est["features"], est["n_rhs"], est["n_far"])
        ratio = sum(meas) / sum(guess)
        ratios.append(ratio)
        f = est["features"]
        print(f"{case[0]:26s} {f['n']:6d} {f['block']:4d} {f['waves']:5d} {f['panels']:3d}  "
              f"{meas[0]:6.2f} {meas[1]:6.2f} {meas[2]:6.2f}   {guess[0]:6.2f} {guess[1]:6.2f} {guess[2]:6.2f}  {ratio:5.2f}")
    print(f"measured / estimated: median {np.median(ratios):.2f}, range {min(ratios):.2f}-{max(ratios):.2f}, "
          f"geometric spread x{math.exp(np.std(np.log(ratios))):.2f}")
    if args.fit:
        print("fitted constants:", {k: float(f"{v:.3g}") for k, v in fit(rows).items()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
