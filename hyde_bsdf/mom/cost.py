"""What a MoM run will cost before it runs: CPU seconds per partition of the fast and dense solvers.

Why: a run of ten 4000-lambda partitions at 15 points per wavelength used to say nothing but "0/10 partitions
done" for a minute; :func:`hyde_bsdf.mom.scatter` now prints this estimate first wherever the run is
expected to take more than a minute (:data:`REPORT_SECONDS`), and :func:`hyde_bsdf.mom.estimate` answers it
without running.  The wall time divides the CPU time over the workers, each at the share of a core the
machine's load average leaves it (:func:`core_share`: on two cores at load 3, two workers get 0.4 each).

The fast solver's time (:mod:`hyde_bsdf.mom.fast`) per partition of N unknowns, with B samples per block
(the strong part holds 3B entries per row), Q plane waves (summed over the regions with a far part),
p quadrature panels per cell for a metal's skin depth (0 for a PEC or glass), R regions (1 PEC, 2 finite
index), n_rhs = incidence angles x polarisations and n_far observation angles (asked + the power grid):

    set-up     N (3B (a_fill R + a_panel p) + a_wave Q)
    solve      N n_rhs (3B a_band + Q a_sweep) R
    far field  N n_far n_rhs a_far

with the constants of :data:`hyde_bsdf.resources.COSTS` (``fast_fill_seconds_per_entry`` ... ``far_field_seconds``)
fitted to measured runs on one core (``benchmarks/bench_mom_estimate.py --fit`` measures them and prints measured
/ estimated; rerun it after a change to the solver and copy what it prints).  Iteration counts vary with the surface (a steep one can fall back to
GMRES): the estimate is good to about a factor of 2, which is what a "this will take ~20 minutes" line needs.
"""
from __future__ import annotations

import math

from hyde_bsdf.mom.fast import NEAR_WL, FastSolverUnsuitable, plan_blocks
from hyde_bsdf.mom.kernels import K0

__all__ = ["REPORT_SECONDS", "constants", "partition_features", "fast_seconds", "core_share", "describe"]

#: a run expected to take longer than this (wall seconds) says so before it starts
REPORT_SECONDS = 60.0


def constants():
    """The model's constants (module docstring) from the one table of costs, :data:`hyde_bsdf.resources.COSTS`."""
    from hyde_bsdf.resources import COSTS

    return dict(a_fill=COSTS.fast_fill_seconds_per_entry, a_panel=COSTS.fast_panel_seconds_per_entry,
                a_wave=COSTS.fast_wave_seconds, a_band=COSTS.fast_band_seconds, a_sweep=COSTS.fast_sweep_seconds,
                a_far=COSTS.far_field_seconds)


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
    c = constants() if c is None else c
    n, strong = f["n"], 3 * f["block"]
    setup = n * (strong * (c["a_fill"] * f["regions"] + c["a_panel"] * f["panels"]) + c["a_wave"] * f["waves"])
    solve = n * n_rhs * (strong * c["a_band"] + f["waves"] * c["a_sweep"]) * f["regions"]
    far = n * n_far * n_rhs * c["a_far"]
    return setup, solve, far


def core_share(workers) -> float:
    """The share of a core each worker can expect now: 1 on an idle machine, cores / (load + workers) when the
    load average and the workers together exceed the cores (a shared machine makes a long run longer)."""
    import os

    cores = os.cpu_count() or 1
    try:
        load = os.getloadavg()[0]
    except (OSError, AttributeError):         # no load average on this platform: assume an idle machine
        load = 0.0
    return min(1.0, cores / max(float(cores), load + workers))


def describe(est) -> str:
    """One line for a run's estimate (``scatter``'s report before it starts)."""
    minutes = est["wall_seconds"] / 60.0
    wall = f"~{minutes:.0f} min" if minutes >= 2 else f"~{est['wall_seconds']:.0f} s"
    load = "" if est["core_share"] >= 1.0 else f" at {est['core_share']:.2g} of a core each (the machine's load)"
    return (f"estimated {wall} wall ({est['cpu_seconds'] / 60.0:.1f} CPU min over {est['workers']} worker(s){load}), "
            f"peak memory ~{est['memory_text']}: {est['partitions']} partition(s) of {est['unknowns']} unknowns, "
            f"{est['method']} solver, {est['n_rhs']} incidence x polarisation, {est['n_far']} far-field angles "
            "(the estimate is good to about a factor of 2)")
