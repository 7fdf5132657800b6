"""Benchmark of hyde_bsdf.mom.scatter on the paper's Fig. 6 case (a benchmark, not a test).

Default: 15,000 lambda, 100 partitions of 150 lambda, 10 points per wavelength
(1500 unknowns per partition), theta_i = 10, 30, 45, 60, 75 deg, 359 observation
angles, the default process pool (one single-threaded-BLAS worker per core).
Target on 2 cores: <= 30 s wall, <= 2 GiB peak memory.

Runs the PEC case s-only and with both polarisations (s, p) in interleaved rounds and prints
the median wall-time ratio (s+p must stay <= 2.5 x s-only), then the Infragold (lossy)
case with both polarisations and its cost breakdown.  Prints the wall time, the worker CPU seconds spent in each stage (matrix fill,
LU factorisation, the solves for all theta_i, the far field of Eq. 21 on the
user's and the power-balance grids), the peak resident memory of the parent and
of the largest worker, and the machine load before and after (other jobs share
the cores: the load says how many).

    .venv/bin/python benchmarks/bench_mom.py [--pts-per-wl 10] [--partitions 100] [--workers N] [--rounds 3]
        [--lossy-partitions 10]
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


def load_reference(rev):
    """The s-only solver of git revision ``rev`` (e.g. 245d8eb, before both polarisations), as a module."""
    import importlib.util
    import subprocess
    import tempfile

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    src = subprocess.run(["git", "-C", root, "show", f"{rev}:hyde_bsdf/mom/solver.py"], check=True,
                         capture_output=True, text=True).stdout
    path = os.path.join(tempfile.mkdtemp(prefix="bench_mom_"), "reference_solver.py")
    with open(path, "w") as fh:
        fh.write(src)
    spec = importlib.util.spec_from_file_location("reference_solver", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["reference_solver"] = mod  # the process pool pickles its functions by module name
    spec.loader.exec_module(mod)
    return mod


def run_case(mom, args, workers, **kw):
    ell = 5.0
    ex = mom.process_pool(workers)
    t0 = time.perf_counter()
    try:
        res = mom.scatter(args.length_wl, args.partitions, 0.3 * ell / math.sqrt(2.0), ell,
                          [10.0, 30.0, 45.0, 60.0, 75.0], np.arange(-89.5, 89.51, 0.5),
                          pts_per_wl=args.pts_per_wl, seed=0, executor=ex, progress=False, **kw)
    finally:
        ex.shutdown(wait=True)
    return res, time.perf_counter() - t0


def report(label, res, wall, workers, partitions):
    t = res.times
    cpu = t["fill"] + t["factor"] + t["solve"] + t["far_field"]
    print(f"{label}: wall {wall:.1f} s, worker CPU {cpu:.1f} s")
    for k in ("fill", "factor", "solve", "far_field"):
        print(f"  {k:10s} {t[k]:7.1f} s  ({1000 * t[k] / partitions:6.1f} ms/partition)  {100 * t[k] / cpu:5.1f} %")
    for pol in res.polarization:
        print(f"  {pol}-pol reflected + absorbed per theta_i:",
              " ".join(f"{e:.4f}" for e in getattr(res, "energy_" + pol)))
    return cpu


def main(argv=None):
    ap = argparse.ArgumentParser(description="benchmark hyde_bsdf.mom.scatter on the Fig. 6 case")
    ap.add_argument("--pts-per-wl", type=float, default=10.0)
    ap.add_argument("--partitions", type=int, default=100)
    ap.add_argument("--length-wl", type=float, default=15000.0)
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds of s-only and s+p (median reported)")
    ap.add_argument("--reference-rev", default="245d8eb",
                    help="git revision whose s-only solver is timed too ('' to skip): the ratio to today's s-only")
    ap.add_argument("--lossy-partitions", type=int, default=10,
                    help="partitions of the Infragold (n = 0.285, k = 7.3523) s+p run (0: skip)")
    args = ap.parse_args(argv)

    from hyde_bsdf import mom

    load0 = load()
    ref = load_reference(args.reference_rev) if args.reference_rev else None
    walls = {"s": [], "sp": [], "ref": []}
    cpus = {"s": [], "sp": [], "ref": []}
    for r in range(args.rounds):
        if ref is not None:
            res, wall = run_case(ref, args, args.workers)
            t = res.times
            cpus["ref"].append(t["fill"] + t["factor"] + t["solve"] + t["far_field"])
            walls["ref"].append(wall)
            print(f"[round {r + 1}] reference ({args.reference_rev}) PEC s: wall {wall:.1f} s, "
                  f"worker CPU {cpus['ref'][-1]:.1f} s")
        for key, pols in (("s", "s"), ("sp", ("s", "p"))):
            res, wall = run_case(mom, args, args.workers, polarization=pols)
            print(f"[round {r + 1}]", end=" ")
            cpus[key].append(report(f"PEC {'+'.join(pols)}", res, wall, args.workers, args.partitions))
            walls[key].append(wall)
    n = res.params["unknowns_per_partition"]
    med = {k: float(np.median(v)) for k, v in walls.items() if v}
    medc = {k: float(np.median(v)) for k, v in cpus.items() if v}
    print(f"case: {args.length_wl:g} lambda, {args.partitions} partitions x {n} unknowns "
          f"({res.params['pts_per_wl']:g} pts/lambda), 5 theta_i, {res.theta_r.size} + {res.fine_theta_r.size} "
          f"observation angles, {args.workers} workers, {args.rounds} interleaved rounds")
    print(f"load average before: {' '.join(load0)}   after: {' '.join(load())}   (cores: {os.cpu_count()})")
    print(f"median wall: s-only {med['s']:.1f} s, s+p {med['sp']:.1f} s -> ratio {med['sp'] / med['s']:.2f}"
          f"; median worker CPU ratio {medc['sp'] / medc['s']:.2f}")
    if ref is not None:
        print(f"against today's s-only solver ({args.reference_rev}): wall {med['ref']:.1f} s -> s+p / reference "
              f"{med['sp'] / med['ref']:.2f} (target <= 2.5), worker CPU ratio {medc['sp'] / medc['ref']:.2f}; "
              f"new s-only / reference {med['s'] / med['ref']:.2f}")
    if args.lossy_partitions > 0:
        sub = argparse.Namespace(**vars(args))
        sub.partitions = args.lossy_partitions
        sub.length_wl = args.length_wl / args.partitions * args.lossy_partitions
        res, wall = run_case(mom, sub, args.workers, polarization=("s", "p"), n=0.285, k=7.3523)
        cpu = report(f"Infragold s+p, {sub.partitions} partitions", res, wall, args.workers, sub.partitions)
        print(f"lossy cost per partition: {cpu / sub.partitions:.2f} CPU s against the PEC s+p "
              f"{medc['sp'] / args.partitions:.2f} (fill = both regions' matrices and the interior solve "
              "(1/2 + D1)^-1 S1 with its banded product; factor = one LU per polarisation)")
    self_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB -> MiB on Linux
    child_rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    print(f"peak RSS: parent {self_rss:.0f} MiB, largest worker {child_rss:.0f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
