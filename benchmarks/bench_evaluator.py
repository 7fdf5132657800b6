"""Benchmark: full 4x4 pBRDF evaluations per second on one core (target >= 2 million/s).

NumPy's element-wise kernels are single-threaded; thread pools of BLAS are pinned to one
thread here anyway.  Prints a table and writes bench_evaluator.csv into OUTDIR.

    .venv/bin/python benchmarks/bench_evaluator.py [-n 2000000] [-o out/bench]
"""
import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import argparse
import csv
import math
import platform
import time
from pathlib import Path

import numpy as np

import hyde_bsdf

CONFIGS = {
    "gold, V-groove + diffuse (default)": dict(n=0.285, k=7.3523),
    "gold, specular only": dict(n=0.285, k=7.3523, diffuse=False),
    "PEC, V-groove + diffuse": dict(pec=True),
    "gold, Smith + diffuse": dict(n=0.285, k=7.3523, shadowing="smith"),
    "gold, reciprocal diffuse": dict(n=0.285, k=7.3523, diffuse="reciprocal"),
}


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("-n", type=int, default=2_000_000, help="directions per call")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("-o", "--outdir", default="out/bench")
    a = ap.parse_args()
    rng = np.random.default_rng(0)
    ti, tr = rng.uniform(0, 0.5 * math.pi, (2, a.n))
    ph = rng.uniform(0, 2 * math.pi, a.n)
    rows = []
    print(f"{platform.processor() or platform.machine()}, numpy {np.__version__}, {a.n} directions per call, "
          f"best of {a.repeat}; load average {os.getloadavg()[0]:.2f}")
    for name, kw in CONFIGS.items():
        hyde_bsdf.pbrdf(ti[:10], tr[:10], ph[:10], rms_slope=0.44, **kw)   # builds/loads the DHR table
        best = float("inf")
        for _ in range(a.repeat):
            t0 = time.perf_counter()
            hyde_bsdf.pbrdf(ti, tr, ph, rms_slope=0.44, **kw)
            best = min(best, time.perf_counter() - t0)
        rate = a.n / best
        rows.append([name, a.n, best, rate])
        print(f"  {name:40s} {rate / 1e6:6.2f} M evaluations/s  ({best * 1e3:.0f} ms)")
    # the fit's residual: the same model as four normalized elements (hyde-bsdf fit's cost per
    # evaluation; a 10^6-row fit makes ~70 such evaluations on all rows, ~400 on 4000 rows)
    from hyde_bsdf.fit import mueller_elements
    names = ("M01", "M11", "M22", "M23")
    mueller_elements(ti[:10], tr[:10], ph[:10], names, rms_slope=0.44, n=0.285, k=7.3523)
    best = float("inf")
    for _ in range(a.repeat):
        t0 = time.perf_counter()
        mueller_elements(ti, tr, ph, names, rms_slope=0.44 + 1e-9 * _, n=0.285, k=7.3523)
        best = min(best, time.perf_counter() - t0)
    rows.append(["fit residual: M01, M11, M22, M23 / M00 (gold)", a.n, best, a.n / best])
    print(f"  {rows[-1][0]:40s} {a.n / best / 1e6:6.2f} M geometries/s  ({best * 1e3:.0f} ms)")
    out = Path(a.outdir)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "bench_evaluator.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["config", "directions", "seconds", "evaluations_per_second"])
        w.writerows(rows)


if __name__ == "__main__":
    main()
