"""Benchmark: ``--model auto`` (every model, the simplest adequate chosen) against one default fit.

A 3,000-geometry, 5-band ``measured_polarized`` table (``hyde-bsdf export``, 25 x 40 x 40, Au) is
fitted side by side, in one process, round after round: the single default fit
(:func:`hyde_bsdf.fit.fit_pbsdf`, shadowing vgroove, diffuse paper: what ``hyde-bsdf fit FILE.pbsdf``
ran before model selection) and :func:`hyde_bsdf.fit.model_selection.select_model_pbsdf` (what it
runs now).  Two tables: one made with the default model (auto's worst case: the chosen model is
the expensive one) and one with Smith shadowing and no diffuse term (the issue's case).  Prints
the median time of each over the rounds and their ratio (target: auto <= 2x the single fit), and
writes bench_fit.csv into OUTDIR.  Wall-clock times on a shared machine are noisy: read the ratio.

    .venv/bin/python benchmarks/bench_fit.py [--rounds 3] [-o out/bench]
"""
import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import argparse
import csv
import statistics
import tempfile
import time
import warnings
from pathlib import Path

from hyde_bsdf.fit.model_selection import select_model_pbsdf
from hyde_bsdf.fit.pbsdf_export import export_pbsdf
from hyde_bsdf.fit.pbsdf_samples import pbsdf_samples
from hyde_bsdf.fit.pbsdf_fit import fit_pbsdf

TABLES = {"default model (vgroove, paper diffuse)": dict(shadowing="vgroove", diffuse="paper"),
          "Smith, no diffuse": dict(shadowing="smith", diffuse="none")}


def timed(fn, *args, **kwargs):
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = fn(*args, **kwargs)
    return time.perf_counter() - t0, out


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--points", type=int, default=3000)
    ap.add_argument("-o", "--outdir", default="out/bench")
    a = ap.parse_args()
    rows = []
    print(f"{a.points} geometries x 5 bands, median of {a.rounds} interleaved rounds; load average "
          f"{os.getloadavg()[0]:.2f}")
    with tempfile.TemporaryDirectory() as folder:
        for label, model in TABLES.items():
            path = Path(folder) / "table.pbsdf"
            export_pbsdf(path, rms_slope=0.2, material="Au", resolution=(25, 40, 40), error_samples=0,
                         alpha_sample=0.3, **model)
            data = pbsdf_samples(path, max_points=a.points)
            timed(select_model_pbsdf, pbsdf_samples(path, max_points=200), progress=False)   # warm-up: DHR tables
            single, auto = [], []
            for _ in range(a.rounds):
                single.append(timed(fit_pbsdf, data, progress=False)[0])
                t, sel = timed(select_model_pbsdf, data, progress=False)
                auto.append(t)
            ms, ma = statistics.median(single), statistics.median(auto)
            rows.append([label, len(data), a.rounds, ms, ma, ma / ms, sel.choice.label])
            print(f"  {label:40s} single default fit {ms:6.2f} s, auto {ma:6.2f} s (chose {sel.choice.label}): "
                  f"ratio {ma / ms:.2f} (target <= 2)")
    out = Path(a.outdir)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "bench_fit.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["table", "geometries", "rounds", "single_default_s", "auto_s", "ratio", "chosen"])
        w.writerows(rows)


if __name__ == "__main__":
    main()
