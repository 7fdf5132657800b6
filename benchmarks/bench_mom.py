"""Benchmark of hyde_bsdf.mom.scatter on the paper's Fig. 6 case: fast and dense solvers against the dense-LU floor.

Default: 15,000 lambda, 100 partitions of 150 lambda, 10 points per wavelength
(1500 unknowns per partition), theta_i = 10, 30, 45, 60, 75 deg, 359 observation
angles, both polarisations, the default process pool (one single-threaded-BLAS worker per core).

Part 1 (interleaved rounds, medians, all in this process):
  * the dense-LU floor: 100 LU factorisations of a 1500 x 1500 complex matrix on the same
    pool (what any dense solver must at least spend, before filling a matrix or solving);
  * the Fig. 6 run with solver="fast" and with solver="dense".
  It prints fast / floor (target <= 1.0), dense / floor and fast / dense, and each
  method's CPU breakdown (fill or set-up, factor, solve, far field).
Part 2: one partition of N unknowns (Fig. 6 surface statistics, both polarisations, one
  theta_i), fast against dense CPU seconds for N up to the largest the dense path fits
  (``--sizes``, default up to 8000; the dense path is refused above 10,000), then the fast solver alone
  (``--fast-sizes``, default 20,000-100,000).

    .venv/bin/python benchmarks/bench_mom.py [--rounds 3] [--partitions 100] [--workers N]
        [--solvers fast,dense] [--sizes 500,1000,2000,4000,8000] [--fast-sizes 20000,50000,100000]
        [--skip-fig6] [--skip-sizes]

Measured (docs/validation.md, "The fast solver"): Fig. 6 s+p, fast 0.80 x the floor in worker CPU
and 0.88 x in wall, dense 3.9 x / 3.7 x (2 rounds at load 4.4-5.2); one partition: fast / dense
0.26 at 1000 unknowns, 0.029 at 4000; 20,000 / 50,000 / 100,000 unknowns 2.3 / 7.8 / 20.1 CPU s.
"""
from __future__ import annotations

import argparse
import math
import os
import resource
import sys
import time

import numpy as np

ELL = 5.0
SIGMA_H = 0.3 * ELL / math.sqrt(2.0)
_LU_MATRIX = {}


def load():
    try:
        return open("/proc/loadavg").read().split()[:3]
    except OSError:
        return ["?"] * 3


def lu_task(n):
    """One LU of an n x n complex matrix (built once per worker; the factorisation copies it)."""
    import scipy.linalg

    if n not in _LU_MATRIX:
        rng = np.random.default_rng(0)
        _LU_MATRIX[n] = rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n))
    t0 = time.process_time()
    scipy.linalg.lu_factor(_LU_MATRIX[n], check_finite=False)
    return time.process_time() - t0


def lu_floor(mom, n, count, workers):
    """Wall seconds of ``count`` LUs of n x n on a fresh pool (matrices built before the clock starts)."""
    ex = mom.process_pool(workers)
    try:
        list(ex.map(lu_task, [n] * workers))      # warm: every worker builds its matrix
        t0 = time.perf_counter()
        cpu = sum(ex.map(lu_task, [n] * count))
        return time.perf_counter() - t0, cpu
    finally:
        ex.shutdown(wait=True)


def fig6(mom, args, solver):
    ex = mom.process_pool(args.workers)
    t0 = time.perf_counter()
    try:
        res = mom.scatter(args.length_wl, args.partitions, SIGMA_H, ELL, [10.0, 30.0, 45.0, 60.0, 75.0],
                          np.arange(-89.5, 89.51, 0.5), pts_per_wl=args.pts_per_wl, seed=0, executor=ex,
                          progress=False, polarization=("s", "p"), solver=solver)
    finally:
        ex.shutdown(wait=True)
    return res, time.perf_counter() - t0


def cpu_of(res):
    t = res.times
    return t["fill"] + t["factor"] + t["solve"] + t["far_field"]


def breakdown(label, res, wall):
    t = res.times
    cpu = cpu_of(res)
    parts = ", ".join(f"{k} {t[k]:.1f} s ({100 * t[k] / cpu:.0f} %)" for k in ("fill", "factor", "solve", "far_field"))
    print(f"  {label}: wall {wall:.1f} s, worker CPU {cpu:.1f} s: {parts}; solver {res.params['solver']}, "
          f"max residual {res.params['max_residual']}")


def one_partition(mom, n, solver, ppw):
    """CPU seconds of one partition of n unknowns (s and p, theta_i = 45 deg), in process."""
    length = n / ppw
    ex = mom.SerialExecutor()
    t0 = time.process_time()
    res = mom.scatter(length, 1, SIGMA_H, ELL, [45.0], [45.0], pts_per_wl=ppw, seed=1, executor=ex,
                      progress=False, polarization=("s", "p"), solver=solver, taper_width_wl=length / 4)
    return time.process_time() - t0, res


def main(argv=None):
    ap = argparse.ArgumentParser(description="benchmark hyde_bsdf.mom.scatter: fast and dense against the LU floor")
    ap.add_argument("--pts-per-wl", type=float, default=10.0)
    ap.add_argument("--partitions", type=int, default=100)
    ap.add_argument("--length-wl", type=float, default=15000.0)
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds (median reported)")
    ap.add_argument("--sizes", default="500,1000,2000,4000,8000", help="N for fast vs dense (one partition; the dense path is refused above 10000)")
    ap.add_argument("--fast-sizes", default="20000,50000,100000", help="N for the fast solver alone")
    ap.add_argument("--skip-fig6", action="store_true")
    ap.add_argument("--skip-sizes", action="store_true")
    ap.add_argument("--solvers", default="fast,dense", help="methods timed against the floor in part 1")
    args = ap.parse_args(argv)

    import warnings

    from hyde_bsdf import mom
    from hyde_bsdf.mom.runtime import keep_freed_memory, limit_blas_threads

    warnings.simplefilter("ignore", mom.MoMAccuracyWarning)
    print(f"load average before: {' '.join(load())} (cores: {os.cpu_count()})")
    if not args.skip_fig6:
        n = int(round(args.length_wl / args.partitions * args.pts_per_wl))
        solvers = [m for m in args.solvers.split(",") if m]
        walls = {k: [] for k in ["floor"] + solvers}
        cpus = {k: [] for k in ["floor"] + solvers}
        for r in range(args.rounds):
            w, cpu = lu_floor(mom, n, args.partitions, args.workers)
            walls["floor"].append(w)
            cpus["floor"].append(cpu)
            print(f"[round {r + 1}] dense-LU floor: {args.partitions} LUs of {n} x {n}: wall {w:.1f} s "
                  f"(worker CPU {cpu:.1f} s)")
            for solver in solvers:
                res, wall = fig6(mom, args, solver)
                walls[solver].append(wall)
                cpus[solver].append(cpu_of(res))
                breakdown(f"[round {r + 1}] Fig. 6 s+p, solver={solver}", res, wall)
                print(f"    reflected + absorbed s: {' '.join(f'{e:.4f}' for e in res.energy_s)}; "
                      f"p: {' '.join(f'{e:.4f}' for e in res.energy_p)}")
        for label, vals, unit in (("median wall", walls, "s"), ("median worker CPU (less sensitive to other jobs)",
                                                              cpus, "CPU s")):
            med = {k: float(np.median(v)) for k, v in vals.items()}
            print(f"Fig. 6 ({args.partitions} x {n} unknowns, s and p, {args.workers} workers, {args.rounds} interleaved "
                  f"rounds), {label}: " + ", ".join(f"{k} {v:.1f} {unit}" for k, v in med.items()))
            ratios = [f"{m} / dense-LU floor = {med[m] / med['floor']:.2f}" + (" (target <= 1.0)" if m == "fast" else "")
                      for m in solvers]
            if "fast" in med and "dense" in med:
                ratios.append(f"fast / dense = {med['fast'] / med['dense']:.2f}")
            print("  " + "; ".join(ratios))
    if not args.skip_sizes:
        previous = limit_blas_threads(1)
        keep_freed_memory()          # as in a pool worker (scatter's default executor)
        print("one partition (s and p, theta_i = 45 deg, Fig. 6 statistics), CPU seconds, one BLAS thread, in this "
              "process (freed memory kept, as in a pool worker):")
        print(f"  {'N':>7s} {'fast':>8s} {'dense':>8s} {'fast/dense':>10s}  fast info")
        for n in [int(s) for s in args.sizes.split(",") if s]:
            tf, rf = one_partition(mom, n, "fast", args.pts_per_wl)
            td, rd = one_partition(mom, n, "dense", args.pts_per_wl)
            db = 10 * np.log10(rf.sigma_s[0, 0] / rd.sigma_s[0, 0])
            print(f"  {n:7d} {tf:8.2f} {td:8.2f} {tf / td:10.3f}  sigma_s(45) fast - dense {db:+.4f} dB, "
                  f"E_s {rf.energy_s[0]:.4f}/{rd.energy_s[0]:.4f}")
        for n in [int(s) for s in args.fast_sizes.split(",") if s]:
            tf, rf = one_partition(mom, n, "fast", args.pts_per_wl)
            t = rf.times
            print(f"  {n:7d} {tf:8.2f} {'-':>8s} {'-':>10s}  set-up {t['fill']:.1f} s, iterations {t['solve']:.1f} s, "
                  f"far field {t['far_field']:.1f} s; E_s {rf.energy_s[0]:.4f}, E_p {rf.energy_p[0]:.4f}")
        from hyde_bsdf.mom.runtime import restore_blas_threads
        restore_blas_threads(previous)
    print(f"load average after: {' '.join(load())}")
    self_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    child_rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    print(f"peak RSS: this process {self_rss:.0f} MiB, largest worker {child_rss:.0f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
