"""Benchmark of hyde_bsdf.mom.scatter on the paper's Fig. 6 case (a benchmark, not a test).

Default: 15,000 lambda, 100 partitions of 150 lambda, 10 points per wavelength
(1500 unknowns per partition), theta_i = 10, 30, 45, 60, 75 deg, 359 observation
angles, the default process pool (one single-threaded-BLAS worker per core).
Target on 2 cores: <= 30 s wall, <= 2 GiB peak memory.

Prints the wall time, the worker CPU seconds spent in each stage (matrix fill,
LU factorisation, the solves for all theta_i, the far field of Eq. 21 on the
user's and the power-balance grids), the peak resident memory of the parent and
of the largest worker, and the machine load before and after (other jobs share
the cores: the load says how many).

    .venv/bin/python benchmarks/bench_mom.py [--pts-per-wl 10] [--partitions 100] [--workers N]
"""
from __future__ import annotations

import argparse
import math
import os
import resource
import sys
import time

import numpy as np


def load():
    try:
        return open("/proc/loadavg").read().split()[:3]
    except OSError:
        return ["?"] * 3


def main(argv=None):
    ap = argparse.ArgumentParser(description="benchmark hyde_bsdf.mom.scatter on the Fig. 6 case")
    ap.add_argument("--pts-per-wl", type=float, default=10.0)
    ap.add_argument("--partitions", type=int, default=100)
    ap.add_argument("--length-wl", type=float, default=15000.0)
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    args = ap.parse_args(argv)

    from hyde_bsdf import mom

    load0 = load()
    ex = mom.process_pool(args.workers)
    ell = 5.0
    t0 = time.perf_counter()
    try:
        res = mom.scatter(args.length_wl, args.partitions, 0.3 * ell / math.sqrt(2.0), ell,
                          [10.0, 30.0, 45.0, 60.0, 75.0], np.arange(-89.5, 89.51, 0.5),
                          pts_per_wl=args.pts_per_wl, seed=0, executor=ex, progress=False)
    finally:
        ex.shutdown(wait=True)
    wall = time.perf_counter() - t0
    load1 = load()
    t = res.times
    cpu = t["fill"] + t["factor"] + t["solve"] + t["far_field"]
    self_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB -> MiB on Linux
    child_rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    n = res.params["unknowns_per_partition"]
    print(f"case: {args.length_wl:g} lambda, {args.partitions} partitions x {n} unknowns "
          f"({res.params['pts_per_wl']:g} pts/lambda), 5 theta_i, {res.theta_r.size} + {res.fine_theta_r.size} "
          f"observation angles, {args.workers} workers")
    print(f"load average before: {' '.join(load0)}   after: {' '.join(load1)}   (cores: {os.cpu_count()})")
    print(f"wall: {wall:.1f} s")
    print("worker CPU seconds (sum over partitions; per partition in brackets):")
    for k in ("fill", "factor", "solve", "far_field"):
        print(f"  {k:10s} {t[k]:7.1f} s  ({1000 * t[k] / args.partitions:6.1f} ms)  {100 * t[k] / cpu:5.1f} %")
    print(f"  {'total':10s} {cpu:7.1f} s  -> parallel efficiency {cpu / (wall * args.workers):.0%} of {args.workers} workers")
    print(f"peak RSS: parent {self_rss:.0f} MiB, largest worker {child_rss:.0f} MiB, "
          f"all processes <= {self_rss + args.workers * child_rss:.0f} MiB")
    print("power balance per theta_i:", " ".join(f"{p:.4f}" for p in res.power_balance))
    return 0


if __name__ == "__main__":
    sys.exit(main())
