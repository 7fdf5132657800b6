"""Measure every entry of :data:`hyde_bsdf.resources.COSTS` and print it beside the table's value.

Each memory figure is the peak resident size (ru_maxrss) of a fresh child process, so that no
earlier work in this process counts; a fixed part and a per-unit part come from two sizes.  Times
are CPU seconds on one core (single-threaded BLAS).  The table keeps a margin above what is
measured: the last column, table / measured, should be >= 1 (a cost that grew past its entry
shows < 1: raise the entry).  After a change that moves a cost, rerun and copy the figures into
``hyde_bsdf/resources.py``.

    .venv/bin/python benchmarks/bench_resources.py [--only render,ad,forward,dense,fast,surface,pbsdf,disk]

Entries not measured here: ``map_bytes_per_texel_*`` (counted: float64 arrays), ``plot_file_bytes``
(an upper bound; the plot ``invert`` writes is printed as a check).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CLI = [sys.executable, "-m", "hyde_bsdf.app.cli"]


def peak_rss(cmd) -> int:
    """Peak resident bytes of the child ``cmd`` (Linux reports ru_maxrss in KiB)."""
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(proc.pid, 0)
    if status != 0:
        raise SystemExit(f"{' '.join(map(str, cmd))} failed: {proc.stderr.read()[-2000:]}")
    return usage.ru_maxrss * 1024


def two_sizes(units, rss):
    """(fixed, per unit) of the line through two (units, bytes) points."""
    per = (rss[1] - rss[0]) / (units[1] - units[0])
    return rss[0] - per * units[0], per


def render(tmp, variant, polarized):
    """``hyde-bsdf render scenes/inverse.xml`` at res 300 and 900, 1 spp."""
    sizes = (300, 900)
    rss = [peak_rss(CLI + ["render", "scenes/inverse.xml", "-o", str(tmp / f"r{r}.exr"), "--variant", variant,
                           "-D", f"res={r}", "--spp", "1", "-q"]) for r in sizes]
    fixed, per = two_sizes([r * r for r in sizes], rss)
    key = "render_stokes_bytes_per_pixel" if polarized else "render_colour_bytes_per_pixel"
    return {"render_fixed_bytes" if polarized else "render_fixed_bytes (colour)": fixed, key: per}


def ad(tmp):
    """``hyde-bsdf invert`` (the built-in scene, reverse mode) at 64^2 and 128^2 px, 32 spp; its history CSV."""
    sizes, spp = (64, 128), 32
    rss = [peak_rss(CLI + ["invert", "--res", str(r), "--spp", str(spp), "--spp-ref", "4", "--iterations", "2",
                           "-o", str(tmp / f"inv{r}"), "-q"]) for r in sizes]
    fixed, per = two_sizes([r * r * spp for r in sizes], rss)
    history = tmp / "inv128" / "invert_history.csv"
    rows = history.read_text().count("\n")
    plot = max((p.stat().st_size for p in (tmp / "inv128").glob("*.png")), default=0)
    return {"ad_fixed_bytes": fixed, "ad_bytes_per_sample": per, "history_row_bytes": history.stat().st_size / rows,
            "plot_file_bytes (invert's plot)": plot}


def forward(tmp):
    """``hyde-bsdf invert --maps`` (the built-in plane, every light): 1 spp steps, the uncertainty step's
    forward-mode renders at 16 spp set the peak; at 48^2 and 96^2 px per picture."""
    from hyde_bsdf.inverse.observations import LIGHTS

    sizes, spp = (48, 96), 16
    rss = [peak_rss(CLI + ["invert", "--maps", "--map-size", "8", "--res", str(r), "--spp", "1", "--spp-ref", "4",
                           "--iterations", "2", "-o", str(tmp / f"maps{r}"), "-q"]) for r in sizes]
    _, per = two_sizes([len(LIGHTS) * r * r * spp for r in sizes], rss)
    return {"ad_forward_bytes_per_sample": per}


def dense():
    """Dense solves of a flat partition on one core: PEC s at 1000 and 2000 unknowns (fill per entry,
    LU per n^3), glass s+p at 1500 (the lossless interior's (1/2 + D1)^-1 S1 per n^3)."""
    import numpy as np

    from hyde_bsdf.mom.dense import solve_dense
    from hyde_bsdf.mom.runtime import limit_blas_threads

    limit_blas_threads(1)

    def solve(n, pols, eta):
        x = (np.arange(n) + 0.5) / 10.0
        zero = np.zeros(n)
        psi = np.exp(1j * 2 * np.pi * x * 0.5)[:, None]
        return solve_dense(x, zero, zero, zero, 0.1, psi, pols, eta, time.process_time)["times"]

    fill, lu = [], []
    for n in (1000, 2000):
        t = solve(n, ("s",), None)
        fill.append(t[0] / n**2)
        lu.append(t[1] / n**3)
    n = 1500
    t = solve(n, ("s", "p"), 1.5 + 0j)
    per_entry = min(fill)
    return {"dense_fill_seconds_per_entry": per_entry, "dense_lu_seconds_per_n3": min(lu),
            "dense_interior_seconds_per_n3": (t[0] - 2 * per_entry * n * n) / n**3}


def fast():
    """One Fig. 6 partition (150 wavelengths at 10 points: 1500 unknowns, sigma_h/ell as the paper's),
    fast solver, s and p, one theta_i: CPU seconds per unknown."""
    from hyde_bsdf import mom
    from hyde_bsdf.mom.runtime import limit_blas_threads
    from hyde_bsdf.mom.solver import SerialExecutor

    limit_blas_threads(1)
    ell = 5.0
    t0 = time.process_time()
    mom.scatter(150.0, 1, 0.3 * ell / math.sqrt(2.0), ell, [30.0], [30.0], pts_per_wl=10, solver="fast",
                polarization=("s", "p"), executor=SerialExecutor(), progress=False)
    return {"fast_seconds_per_unknown": (time.process_time() - t0) / 1500}


def surface():
    """Peak bytes per point of drawing a surface with its derivatives (tracemalloc, 2^20 points)."""
    import tracemalloc

    from hyde_bsdf.mom.solver import gaussian_surface

    points = 2**20
    tracemalloc.start()
    gaussian_surface(points / 10.0, points, 0.5, 3.0, 0, second_derivative=True)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return {"surface_bytes_per_point": peak / points}


LOADER = r"""
import resource, sys
import mitsuba as mi
mi.set_variant("scalar_spectral_polarized")
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
bsdf = mi.load_dict({"type": "measured_polarized", "filename": sys.argv[1]})
print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) * 1024)
"""


def pbsdf(tmp):
    """Mitsuba loading a ~40 MB ``.pbsdf``: the rise of its peak RSS over the file size."""
    from hyde_bsdf.fit.pbsdf_export import export_pbsdf

    path = tmp / "table.pbsdf"
    export_pbsdf(path, rms_slope=0.3, n=1.5, resolution=(90, 45, 45), progress=False)
    rise = int(subprocess.run([sys.executable, "-c", LOADER, str(path)], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.split()[-1])
    return {"pbsdf_loader_copies": rise / path.stat().st_size}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", default="render,ad,forward,dense,fast,surface,pbsdf")
    args = ap.parse_args(argv)
    from hyde_bsdf.resources import COSTS

    measured = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        steps = {"render": lambda: {**render(tmp, "llvm_ad_spectral_polarized", True),
                                    **render(tmp, "llvm_ad_rgb", False)},
                 "ad": lambda: ad(tmp), "forward": lambda: forward(tmp), "dense": dense, "fast": fast,
                 "surface": surface, "pbsdf": lambda: pbsdf(tmp)}
        for name in args.only.split(","):
            t0 = time.perf_counter()
            measured.update(steps[name]())
            print(f"[bench_resources] {name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    print(f"load average {os.getloadavg()[0]:.1f}, {os.cpu_count()} cores")
    print(f"{'entry':42s} {'measured':>12s} {'table':>12s} {'table/measured':>15s}")
    for key, value in measured.items():
        entry = getattr(COSTS, key.split(" ")[0], None)
        ratio = f"{entry / value:15.2f}" if entry is not None and value > 0 else f"{'':15s}"
        print(f"{key:42s} {value:12.4g} {'' if entry is None else f'{entry:12.4g}':>12s} {ratio}")
    print(json.dumps({k: float(v) for k, v in measured.items()}))


if __name__ == "__main__":
    main()
