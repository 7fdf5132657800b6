"""What a MoM run will cost before it runs: CPU seconds per partition of the fast and dense solvers.

Why: a run of ten 4000-lambda partitions at 15 points per wavelength used to say nothing but "0/10 partitions
done" for a minute; :func:`hyde_bsdf.mom.scatter` now prints this estimate first wherever the run is
expected to take more than a minute (:data:`REPORT_SECONDS`), and :func:`hyde_bsdf.mom.estimate` answers it
without running.

The fast solver's time (:mod:`hyde_bsdf.mom.fast`) per partition of N unknowns, with B samples per block
(the strong part holds 3B entries per row), Q plane waves (summed over the regions with a far part),
p quadrature panels per cell for a metal's skin depth (0 for a PEC or glass), R regions (1 PEC, 2 finite
index), n_rhs = incidence angles x polarisations and n_far observation angles (asked + the power grid):

    set-up     N (3B (a_fill R + a_panel p) + a_wave Q)
    solve      N n_rhs (3B a_band + Q a_sweep) R
    far field  N n_far n_rhs a_far

with the constants of :data:`FAST_CONSTANTS` fitted to measured runs on one core
(``benchmarks/bench_mom_estimate.py`` measures them and prints measured / estimated; rerun it after a change
to the solver and copy what it prints).  Iteration counts vary with the surface (a steep one can fall back to
GMRES): the estimate is good to about a factor of 2, which is what a "this will take ~20 minutes" line needs.
"""
from __future__ import annotations

import math

from hyde_bsdf.mom.fast import NEAR_WL, FastSolverUnsuitable, plan_blocks
from hyde_bsdf.mom.kernels import K0

__all__ = ["FAST_CONSTANTS", "REPORT_SECONDS", "partition_features", "fast_seconds", "describe"]

#: a run expected to take longer than this (wall seconds) says so before it starts
REPORT_SECONDS = 60.0
#: seconds per unit of each term of the fast solver's time (module docstring); benchmarks/bench_mom_estimate.py
FAST_CONSTANTS = dict(a_fill=6.76e-7, a_panel=7.72e-7, a_wave=0.0, a_band=1.37e-9, a_sweep=2.9e-8, a_far=5.65e-10)


def partition_features(n, dx, height_wl, partition_wl, eta, stretch, method):
    """The cost model's inputs for one partition: dict n, block (B), waves (Q), panels (p), regions (R), method."""
    regions = 1 if eta is None else 2
    panels = 0 if eta is None or eta.imag == 0 else math.ceil(-eta.imag * K0 * dx * stretch)
    out = dict(n=int(n), panels=panels, regions=regions, method=method, block=0, waves=0)
    if method == "fast":
        ks = [K0] if eta is None or eta.imag != 0 else [K0, K0 * eta]
        try:
            b, rules = plan_blocks(int(n), dx, height_wl, partition_wl, ks, NEAR_WL)
        except FastSolverUnsuitable:
            out["method"] = "dense"
        else:
            out.update(block=int(b), waves=int(sum(phi.size for phi, _ in rules)))
    return out


def fast_seconds(f, n_rhs, n_far, c=None):
    """(set-up, solve, far field) CPU seconds of one fast partition with features ``f``."""
    c = FAST_CONSTANTS if c is None else c
    n, strong = f["n"], 3 * f["block"]
    setup = n * (strong * (c["a_fill"] * f["regions"] + c["a_panel"] * f["panels"]) + c["a_wave"] * f["waves"])
    solve = n * n_rhs * (strong * c["a_band"] + f["waves"] * c["a_sweep"]) * f["regions"]
    far = n * n_far * n_rhs * c["a_far"]
    return setup, solve, far


def describe(est) -> str:
    """One line for a run's estimate (``scatter``'s report before it starts)."""
    minutes = est["wall_seconds"] / 60.0
    wall = f"~{minutes:.0f} min" if minutes >= 2 else f"~{est['wall_seconds']:.0f} s"
    return (f"estimated {wall} wall ({est['cpu_seconds'] / 60.0:.1f} CPU min over {est['workers']} worker(s)), "
            f"peak memory ~{est['memory_text']}: {est['partitions']} partition(s) of {est['unknowns']} unknowns, "
            f"{est['method']} solver, {est['n_rhs']} incidence x polarisation, {est['n_far']} far-field angles "
            "(the estimate is good to about a factor of 2)")
