"""Benchmark: the fast MoM on a rough glass surface at grazing incidence (issue 25's case), with no dense fallback.

Glass n = 1.5, sigma_h = 2 lambda, ell = 14.1 lambda (rms slope 0.2, height range ~11 lambda), theta_i = 85 deg,
taper w = 241 lambda, 2 partitions of 966 lambda, 8 points per wavelength (7,728 unknowns each), s and p,
solver="fast", in this process (SerialExecutor: the peak RSS is one worker's).  It prints the CPU seconds, the
peak resident memory, the method used and reflected + transmitted power per polarisation.  Targets: <= 60 CPU s,
<= 2 GB, no dense fallback, energy within 1 % (the dense LU fallback it replaced took 776 s and 7.9 GB).

    .venv/bin/python benchmarks/bench_mom_glass.py [--seed 0] [--pts-per-wl 8] [--tol T] [--incidence auto|beam|window]

Measured (docs/validation.md, issue 25): seed 0, beam (the default at 85 deg) 13.6-15.3 CPU s, 1.52 GiB, energy
1.0053 / 1.0046; seed 4 18.4 s, 1.72 GiB, 1.0047 / 1.0039; the windowed current 18.4 s, 1.0207 / 1.0181.
"""
from __future__ import annotations

import argparse
import resource
import time
import warnings

import numpy as np

from hyde_bsdf import mom


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pts-per-wl", type=float, default=8.0)
    ap.add_argument("--tol", type=float, default=None)
    ap.add_argument("--incidence", default="auto")
    args = ap.parse_args(argv)
    t0 = time.process_time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", mom.MoMAccuracyWarning)
        res = mom.scatter(1932.0, 2, 2.0, 14.1, [85.0], np.arange(-89.0, 90.0, 1.0), pts_per_wl=args.pts_per_wl,
                          seed=args.seed, tol=args.tol,
                          executor=mom.SerialExecutor(), taper_width_wl=241.0, polarization=("s", "p"), n=1.5, k=0.0,
                          solver="fast", progress=False, incidence=args.incidence)
    cpu = time.process_time() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(f"unknowns per partition {res.params['unknowns_per_partition']}, solver {res.params['solver']}, "
          f"max residual {res.params['max_residual']:.2g}")
    print(f"CPU {cpu:.1f} s (target <= 60), peak RSS {peak:.2f} GiB (target <= 2)")
    print(f"energy s {res.energy_s[0]:.4f}, p {res.energy_p[0]:.4f} (target within 0.01 of 1)")
    for w in caught:
        print("warning:", w.message)


if __name__ == "__main__":
    main()
